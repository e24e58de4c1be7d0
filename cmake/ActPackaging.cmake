# Debian package of the library, its headers, CMake package files and the apps (CPack's DEB generator):
#
#   cmake --build build --target package      -> build/actengine_<version>_<arch>.deb
#
# The architecture is the target's, so a tree configured with
# --toolchain cmake/toolchains/aarch64-linux-gnu.cmake gives actengine_<version>_arm64.deb
# (scripts/build_packages.sh builds both). Runtime dependencies come from dpkg-shlibdeps, which reads
# the arm64 libraries' package data from the multiarch install (scripts/install_cross_deps.sh).
# A new app only needs its install(TARGETS ...) rule in apps/CMakeLists.txt; if it links a library the
# cross build takes from multiarch, add that library's :arm64 -dev package to install_cross_deps.sh
# and dpkg-shlibdeps finds its runtime package. OpenCV is the exception: its arm64 libraries are
# unpacked, not installed (cmake/toolchains/aarch64-linux-gnu/opencv), so dpkg knows nothing of them
# and their runtime packages are named here instead.
set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME actengine)
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
set(CPACK_PACKAGE_VENDOR "actengine")
set(CPACK_PACKAGE_CONTACT "actengine maintainers <actengine@users.noreply.github.com>")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY
    "LeRobot ACT policy inference engine: libactengine, headers, act_convert, act_eval, act_bench, act_drive")
set(CPACK_DEBIAN_PACKAGE_DESCRIPTION
    "Runs LeRobot's ACT (Action Chunking Transformer) policies on a robot's CPU from an .actb blob.\n\
act_convert turns a LeRobot checkpoint folder or a PyTorch .pth into a blob; act_bench measures it;\n\
act_drive runs it on a robot: camera, control loop, PWM over serial to an Arduino.")
set(CPACK_DEBIAN_PACKAGE_SECTION science)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)  # actengine_<version>_<arch>.deb
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
set(CPACK_DEBIAN_PACKAGE_GENERATE_SHLIBS ON)  # shlibs file and the ldconfig trigger for libactengine.so
if(CMAKE_SYSTEM_PROCESSOR MATCHES "^(aarch64|arm64)$")
  set(CPACK_DEBIAN_PACKAGE_ARCHITECTURE arm64)  # CPack would ask the host's dpkg otherwise
elseif(CMAKE_SYSTEM_PROCESSOR MATCHES "^(x86_64|AMD64|amd64)$")
  set(CPACK_DEBIAN_PACKAGE_ARCHITECTURE amd64)
endif()
if(CMAKE_CROSSCOMPILING AND TARGET act_drive AND ACT_OPENCV_DEB_DEPENDS)
  set(CPACK_DEBIAN_PACKAGE_DEPENDS "${ACT_OPENCV_DEB_DEPENDS}")
  set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS_PRIVATE_DIRS "${ACT_OPENCV_LIBDIR}")  # found there, left to DEPENDS
endif()
include(CPack)
