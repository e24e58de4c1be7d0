# CMake toolchain file: cross-compiles for 64-bit ARM Linux (Raspberry Pi 5, Cortex-A76) with
# Debian's cross compiler (g++-aarch64-linux-gnu) against Debian multiarch arm64 libraries, and
# runs the results under qemu-user. scripts/install_cross_deps.sh installs what it expects.
#
#   cmake -S . -B build-aarch64 -G Ninja -DACT_CORE_ONLY=ON \
#         --toolchain cmake/toolchains/aarch64-linux-gnu.cmake
#
# Code generation stays at the architecture baseline (armv8-a, Debian's default): faster
# instructions (dotprod, i8mm) belong in per-file flags behind run-time CPU detection, never in
# global flags, or the library would not start on older cores. Per-ISA sources should be chosen by
# CMAKE_SYSTEM_PROCESSOR (aarch64 here), not by the host's processor.
#
# Setting (-D on the first configure, or an environment variable of the same name):
#   ACT_QEMU_CPU  CPU model qemu emulates when tests run: max (default; every feature qemu has,
#                 dotprod and SVE included), cortex-a76 (the Raspberry Pi 5's exact feature set),
#                 cortex-a72 (Raspberry Pi 4: NEON without dotprod, for the fallback paths)
#   ACT_ARM64_OPENCV_ROOT  where scripts/fetch_arm64_opencv.sh unpacked the arm64 OpenCV libraries
#                 (DIR/root); needed only for the apps that use OpenCV (act_convert, act_drive)

set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR aarch64)

set(ACT_CROSS_TRIPLET aarch64-linux-gnu)  # of the compiler and of Debian's multiarch folders
if(NOT DEFINED ACT_QEMU_CPU AND DEFINED ENV{ACT_QEMU_CPU})
  set(ACT_QEMU_CPU "$ENV{ACT_QEMU_CPU}")
endif()
if(NOT ACT_QEMU_CPU)
  set(ACT_QEMU_CPU max)
endif()
# try_compile() projects re-read this file: hand them the setting too.
list(APPEND CMAKE_TRY_COMPILE_PLATFORM_VARIABLES ACT_QEMU_CPU)

set(CMAKE_C_COMPILER ${ACT_CROSS_TRIPLET}-gcc)
set(CMAKE_CXX_COMPILER ${ACT_CROSS_TRIPLET}-g++)
set(CMAKE_LIBRARY_ARCHITECTURE ${ACT_CROSS_TRIPLET})

# Libraries: Debian multiarch keeps arm64 packages in /usr/lib/<triplet> (zlib and gtest, with
# their CMake and pkg-config files), the cross toolchain keeps its own libc and libstdc++ in
# /usr/<triplet>. Header-only dependencies (xsimd, nlohmann-json) are architecture-independent and
# come from the host's /usr/include and /usr/share. CMAKE_LIBRARY_ARCHITECTURE makes find_library
# and find_package search /usr/lib/<triplet>, never the host's /usr/lib/x86_64-linux-gnu; the find
# root adds /usr/<triplet>. BOTH: the root first, then the normal (multiarch) paths.
set(CMAKE_FIND_ROOT_PATH /usr/${ACT_CROSS_TRIPLET})
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)  # build tools (python, ninja) are the host's
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY BOTH)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE BOTH)
set(CMAKE_FIND_ROOT_PATH_MODE_PACKAGE BOTH)

# cpuinfo: Debian's libcpuinfo-dev cannot be multiarch-installed (see
# aarch64-linux-gnu/cpuinfo/cpuinfo-config.cmake), so the files beside this one stand in for the
# arm64 one: find_package(cpuinfo) -> cpuinfo::cpuinfo, pkg-config libcpuinfo, find_library(cpuinfo)
# and a plain -lcpuinfo all get libcpuinfo0:arm64's library, never the host's x86-64 package files.
set(_act_cross_files "${CMAKE_CURRENT_LIST_DIR}/${ACT_CROSS_TRIPLET}")
set(cpuinfo_DIR "${_act_cross_files}/cpuinfo")
list(APPEND CMAKE_IGNORE_PATH /usr/lib/cmake/cpuinfo)
list(APPEND CMAKE_LIBRARY_PATH "${_act_cross_files}/lib")
foreach(kind EXE SHARED MODULE)
  set(CMAKE_${kind}_LINKER_FLAGS_INIT "-L${_act_cross_files}/lib")
endforeach()

# OpenCV (act_convert, act_drive): libopencv-dev:arm64 cannot be installed beside the host's either;
# opencv/OpenCVConfig.cmake links the arm64 libraries scripts/fetch_arm64_opencv.sh unpacks into
# ACT_ARM64_OPENCV_ROOT (-D or environment), with the host's headers.
set(OpenCV_DIR "${_act_cross_files}/opencv")
list(APPEND CMAKE_TRY_COMPILE_PLATFORM_VARIABLES ACT_ARM64_OPENCV_ROOT)

# pkg-config (FindPkgConfig) must report the target's .pc files, not the host's.
set(ENV{PKG_CONFIG_LIBDIR} "${_act_cross_files}/lib/pkgconfig:\
/usr/lib/${ACT_CROSS_TRIPLET}/pkgconfig:/usr/share/pkgconfig")
set(ENV{PKG_CONFIG_PATH} "")

# Run target binaries (ctest, gtest_discover_tests, add_custom_command) under qemu-user with the
# Debian arm64 runtime that multiarch installs: libc6:arm64 and libstdc++6:arm64 provide the loader
# /lib/ld-linux-aarch64.so.1 and the libraries in /usr/lib/<triplet>, as on the board. No
# "-L /usr/<triplet>": once libc6:arm64 is installed (zlib1g-dev:arm64 needs it), the cross
# toolchain's loader found that way loads the multiarch libc.so.6 of another glibc build through
# /etc/ld.so.cache, and the mismatched pair hangs in the first pthread_create.
find_program(ACT_QEMU_AARCH64 NAMES qemu-aarch64 qemu-aarch64-static)
if(NOT ACT_QEMU_AARCH64)
  set(ACT_QEMU_AARCH64 qemu-aarch64)  # not installed yet: configure anyway; running tests will tell
endif()
set(CMAKE_CROSSCOMPILING_EMULATOR "${ACT_QEMU_AARCH64};-cpu;${ACT_QEMU_CPU}")
