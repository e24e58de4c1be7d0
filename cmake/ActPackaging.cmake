# Debian packages (CPack's DEB generator), one per install component (engine/CMakeLists.txt,
# apps/CMakeLists.txt):
#
#   libactengine0     the shared libraries, in /usr/lib/<multiarch triplet>
#   libactengine-dev  headers, static libraries, .so links, the CMake package, actengine.pc
#   actengine-tools   act_convert, act_eval, act_bench, act_drive (and act_pwm_watchdog, which it starts;
#                     libact_media_io.so, their image and video module, in /usr/lib/<triplet>/actengine)
#
#   cpack -G DEB (in a build tree)  -> <name>_<version>_<arch>.deb for each
#
# The architecture is the target's, so a tree configured with
# --toolchain cmake/toolchains/aarch64-linux-gnu.cmake gives the arm64 packages (scripts/build_packages.sh
# builds both). Programs and libraries are stripped; debug symbols are left out (Release has none).
# Runtime dependencies come from dpkg-shlibdeps on what each package's binaries link; for the arm64
# build it reads the arm64 libraries' package data from the multiarch install
# (scripts/install_cross_deps.sh). A new app only needs its install(TARGETS ... COMPONENT tools) rule;
# if it links a library the cross build takes from multiarch, add that library's :arm64 -dev package
# to install_cross_deps.sh and dpkg-shlibdeps finds its runtime package. OpenCV is the exception: its
# arm64 libraries are unpacked, not installed (cmake/toolchains/aarch64-linux-gnu/opencv), so dpkg
# knows nothing of them and their runtime packages are named here instead.
set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME actengine)
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
set(CPACK_PACKAGE_VENDOR "actengine")
set(CPACK_PACKAGE_CONTACT "actengine maintainers <actengine@users.noreply.github.com>")
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_STRIP_FILES ON)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)  # <package>_<version>_<arch>.deb
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
set(CPACK_DEBIAN_PACKAGE_GENERATE_SHLIBS ON)  # shlibs file and the ldconfig trigger for the libraries
if(CMAKE_SYSTEM_PROCESSOR MATCHES "^(aarch64|arm64)$")
  set(CPACK_DEBIAN_PACKAGE_ARCHITECTURE arm64)  # CPack would ask the host's dpkg otherwise
elseif(CMAKE_SYSTEM_PROCESSOR MATCHES "^(x86_64|AMD64|amd64)$")
  set(CPACK_DEBIAN_PACKAGE_ARCHITECTURE amd64)
endif()

set(CPACK_DEB_COMPONENT_INSTALL ON)
set(CPACK_COMPONENTS_ALL runtime dev)
if(ACT_BUILD_APPS)
  list(APPEND CPACK_COMPONENTS_ALL tools)
endif()
# The -dev package depends on the exact libactengine0 it was built with.
set(CPACK_COMPONENT_DEV_DEPENDS runtime)
set(CPACK_DEBIAN_ENABLE_COMPONENT_DEPENDS ON)

set(CPACK_DEBIAN_RUNTIME_PACKAGE_NAME libactengine${PROJECT_VERSION_MAJOR})  # the libraries' SOVERSION
set(CPACK_DEBIAN_RUNTIME_PACKAGE_SECTION libs)
set(CPACK_DEBIAN_RUNTIME_DESCRIPTION "LeRobot ACT policy inference engine: shared libraries
 libactengine runs a LeRobot ACT (Action Chunking Transformer) policy from an .actb blob on a
 robot's CPU, in FP32 or INT8; libactengine_convert makes the blob from a checkpoint.")

set(CPACK_DEBIAN_DEV_PACKAGE_NAME libactengine-dev)
set(CPACK_DEBIAN_DEV_PACKAGE_SECTION libdevel)
# What the CMake package and the static libraries need to link (find_dependency(ZLIB), cpuinfo).
set(act_dev_depends "zlib1g-dev")
if(ACT_CPUINFO_LIBRARIES)
  string(APPEND act_dev_depends ", libcpuinfo-dev")
endif()
set(CPACK_DEBIAN_DEV_PACKAGE_DEPENDS "${act_dev_depends}")
set(CPACK_DEBIAN_DEV_PACKAGE_SUGGESTS "libopencv-dev")  # for actengine::actengine_vision
set(CPACK_DEBIAN_DEV_DESCRIPTION "LeRobot ACT policy inference engine: development files
 Headers, static libraries, the CMake package (find_package(actengine)) and the pkg-config file
 (actengine.pc) of libactengine.")

set(CPACK_DEBIAN_TOOLS_PACKAGE_NAME actengine-tools)
set(CPACK_DEBIAN_TOOLS_PACKAGE_SECTION science)
set(CPACK_DEBIAN_TOOLS_DESCRIPTION "LeRobot ACT policy inference engine: command-line tools
 act_convert turns a LeRobot checkpoint folder or a PyTorch .pth into an .actb blob (FP32 or INT8);
 act_eval and act_bench run and time it; act_drive runs it on a robot: camera, control loop, PWM over
 serial to an Arduino.")

if(CMAKE_CROSSCOMPILING AND ACT_OPENCV_DEB_DEPENDS)
  # The tools (with their image and video module) link the four OpenCV libraries of depends.txt,
  # libactengine_vision only core and imgproc.
  set(CPACK_DEBIAN_TOOLS_PACKAGE_DEPENDS "${ACT_OPENCV_DEB_DEPENDS}")
  string(REGEX MATCHALL "libopencv-(core|imgproc)[0-9]+ \\([^)]*\\)" act_vision_depends "${ACT_OPENCV_DEB_DEPENDS}")
  list(JOIN act_vision_depends ", " act_vision_depends)
  set(CPACK_DEBIAN_RUNTIME_PACKAGE_DEPENDS "${act_vision_depends}")
  set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS_PRIVATE_DIRS "${ACT_OPENCV_LIBDIR}")  # found there, left to DEPENDS
endif()
include(CPack)
