# cpuinfo for the aarch64 cross build (cmake/toolchains/aarch64-linux-gnu.cmake sets cpuinfo_DIR).
#
# Debian bookworm's libcpuinfo-dev is "Multi-Arch: same" but ships its CMake package files in the
# architecture-less /usr/lib/cmake/cpuinfo with its own architecture's library paths inside, so
# libcpuinfo-dev:arm64 cannot be installed next to the host's libcpuinfo-dev (dpkg refuses to
# overwrite the shared, different cpuinfo-targets-none.cmake), and those files would point a cross
# build at x86-64 libraries. The cross build installs only the library (libcpuinfo0:arm64, which
# co-installs cleanly) and takes the header from the host's libcpuinfo-dev (cpuinfo.h is the same
# file for every architecture). This defines the Debian package's imported target, cpuinfo::cpuinfo.
set(_act_cpuinfo_lib "/usr/lib/${CMAKE_LIBRARY_ARCHITECTURE}/libcpuinfo.so.0")
find_path(_act_cpuinfo_include cpuinfo.h)
if(NOT EXISTS "${_act_cpuinfo_lib}" OR NOT _act_cpuinfo_include)
  set(cpuinfo_FOUND FALSE)
  set(cpuinfo_NOT_FOUND_MESSAGE "needs ${_act_cpuinfo_lib} (libcpuinfo0 of the target \
architecture) and cpuinfo.h (libcpuinfo-dev): run scripts/install_deps.sh")
  return()
endif()
if(NOT TARGET cpuinfo::cpuinfo)
  add_library(cpuinfo::cpuinfo SHARED IMPORTED)
  set_target_properties(cpuinfo::cpuinfo PROPERTIES
    IMPORTED_LOCATION "${_act_cpuinfo_lib}"
    IMPORTED_SONAME "libcpuinfo.so.0"
    INTERFACE_COMPILE_DEFINITIONS "CPUINFO_SUPPORTED_PLATFORM=1"
    INTERFACE_INCLUDE_DIRECTORIES "${_act_cpuinfo_include}")
endif()
set(cpuinfo_FOUND TRUE)
