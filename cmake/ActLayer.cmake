# act_add_layer(name DIR dir | DIRS dir... [DEPS ...]): one OBJECT library per architectural layer,
# holding every .cc file directly in the given folder(s). The layers are linked together into
# libactengine. Per-ISA kernel files get their instruction-set flags (act_set_isa_flags).
function(act_add_layer name)
  cmake_parse_arguments(ARG "" "DIR" "DIRS;DEPS" ${ARGN})
  set(sources)
  foreach(dir ${ARG_DIR} ${ARG_DIRS})
    file(GLOB dir_sources CONFIGURE_DEPENDS ${dir}/*.cc)
    list(APPEND sources ${dir_sources})
  endforeach()
  add_library(${name} OBJECT ${sources})
  target_include_directories(${name} PUBLIC
    $<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}>
    $<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}/engine/include>)
  target_link_libraries(${name} PUBLIC ${ARG_DEPS})
  act_set_warnings(${name})
  act_set_isa_flags(${sources})
endfunction()

# act_set_isa_flags(source...): per-file instruction-set flags, chosen by the file name's suffix
# (the kernel naming grammar's ISA suffix: the level the code needs, kernels/common/isa.h):
#   *_avx2.cc        -mavx2 -mfma                                              (x86-64 targets)
#   *_avx512.cc      -mavx2 -mfma -mavx512f -mavx512bw -mavx512vl              (x86-64 targets)
#   *_avx512vnni.cc  -mavx2 -mfma -mavx512f -mavx512bw -mavx512vl -mavx512vnni (x86-64 targets)
#   *_neon.cc        none: Advanced SIMD is part of the AArch64 baseline
#   *_neondot.cc     -march=armv8.2-a+dotprod                                  (AArch64 targets)
# On other targets the file compiles to nothing but its null table (its body is guarded by
# #if defined(__x86_64__) / defined(__aarch64__)). Only these files see the flags, so the rest of the
# library runs on any CPU of the target architecture.
# Must be called from the directory that creates the target using the sources.
function(act_set_isa_flags)
  if(CMAKE_SYSTEM_PROCESSOR MATCHES "^(x86_64|AMD64|amd64)$")
    set(act_x86 TRUE)
  endif()
  if(CMAKE_SYSTEM_PROCESSOR MATCHES "^(aarch64|arm64|ARM64)$")
    set(act_arm64 TRUE)
  endif()
  foreach(src ${ARGN})
    if(act_x86 AND src MATCHES "_avx2\\.cc$")
      set_source_files_properties(${src} PROPERTIES COMPILE_OPTIONS "-mavx2;-mfma")
    elseif(act_x86 AND src MATCHES "_avx512\\.cc$")
      set_source_files_properties(${src} PROPERTIES COMPILE_OPTIONS "-mavx2;-mfma;-mavx512f;-mavx512bw;-mavx512vl")
    elseif(act_x86 AND src MATCHES "_avx512vnni\\.cc$")
      set_source_files_properties(${src} PROPERTIES COMPILE_OPTIONS
        "-mavx2;-mfma;-mavx512f;-mavx512bw;-mavx512vl;-mavx512vnni")
    elseif(act_arm64 AND src MATCHES "_neondot\\.cc$")
      set_source_files_properties(${src} PROPERTIES COMPILE_OPTIONS "-march=armv8.2-a+dotprod")
    endif()
  endforeach()
endfunction()
