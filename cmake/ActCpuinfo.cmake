# CPU feature detection library (Debian: libcpuinfo-dev). Sets ACT_CPUINFO_LIBRARIES and
# ACT_CPUINFO_INCLUDE_DIRS, or leaves them empty when cpuinfo is missing or cannot be linked for
# the target (e.g. a cross build without the target's libcpuinfo); kernels/common/isa.cc then
# falls back to CPUID (x86) or getauxval(AT_HWCAP) (Linux AArch64).
# Absolute library paths (not an imported target) so the exported static library stays usable.
set(ACT_CPUINFO_LIBRARIES "")
set(ACT_CPUINFO_INCLUDE_DIRS "")
find_package(PkgConfig QUIET)
if(PKG_CONFIG_FOUND)
  pkg_check_modules(ACT_CPUINFO_PC QUIET libcpuinfo)
endif()
if(ACT_CPUINFO_PC_FOUND)
  set(act_cpuinfo_libs ${ACT_CPUINFO_PC_LINK_LIBRARIES})
  set(act_cpuinfo_incs ${ACT_CPUINFO_PC_INCLUDE_DIRS})
else()
  find_library(ACT_CPUINFO_LIBRARY cpuinfo)
  find_path(ACT_CPUINFO_INCLUDE_DIR cpuinfo.h)
  if(ACT_CPUINFO_LIBRARY AND ACT_CPUINFO_INCLUDE_DIR)
    set(act_cpuinfo_libs ${ACT_CPUINFO_LIBRARY})
    set(act_cpuinfo_incs ${ACT_CPUINFO_INCLUDE_DIR})
  endif()
endif()
if(act_cpuinfo_libs)
  # Link check for the target: a host library found by a cross build must not be used.
  include(CheckCXXSourceCompiles)
  set(CMAKE_REQUIRED_LIBRARIES ${act_cpuinfo_libs})
  set(CMAKE_REQUIRED_INCLUDES ${act_cpuinfo_incs})
  set(CMAKE_REQUIRED_QUIET ON)
  check_cxx_source_compiles("#include <cpuinfo.h>\nint main() { return cpuinfo_initialize() ? 0 : 1; }"
                            ACT_CPUINFO_LINKS)
  unset(CMAKE_REQUIRED_LIBRARIES)
  unset(CMAKE_REQUIRED_INCLUDES)
  unset(CMAKE_REQUIRED_QUIET)
  if(ACT_CPUINFO_LINKS)
    set(ACT_CPUINFO_LIBRARIES ${act_cpuinfo_libs})
    set(ACT_CPUINFO_INCLUDE_DIRS ${act_cpuinfo_incs})
  endif()
endif()
if(ACT_CPUINFO_LIBRARIES)
  message(STATUS "cpuinfo: ${ACT_CPUINFO_LIBRARIES}")
else()
  message(WARNING "libcpuinfo not found or not linkable for this target: CPU features come from "
                  "CPUID / getauxval only (install libcpuinfo-dev for the target)")
endif()
