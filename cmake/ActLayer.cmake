# The layers' include roots. Each layer's headers are reachable only through a root of its own in the
# build tree, <build>/layer_include/<root>/, which holds the layer's folder (at its path in the source
# tree, so that "kernels/gemm_s8/gemm_s8.h" is spelled as in the sources) with a link to each of its
# headers and sub-folders, and nothing else of the source tree. A layer sees its own root and, through
# its DEPS, the roots of the layers below it, never those above; cmake/check_layer_includes.py (ctest
# layer_includes) checks the include lines against the same rules.
set(ACT_LAYER_INCLUDE_DIR ${PROJECT_BINARY_DIR}/layer_include)

# act_layer_root(out root folder [HEADERS_ONLY] [EXCLUDE entry...]): makes the root <root> holding
# <folder> (relative to the source dir) with a link to each header and sub-folder of it except the
# EXCLUDEd names (HEADERS_ONLY: no sub-folders); its path in `out`.
function(act_layer_root out root folder)
  cmake_parse_arguments(ARG "HEADERS_ONLY" "" "EXCLUDE" ${ARGN})
  set(dir ${ACT_LAYER_INCLUDE_DIR}/${root})
  file(REMOVE_RECURSE ${dir})
  file(MAKE_DIRECTORY ${dir}/${folder})
  file(GLOB entries CONFIGURE_DEPENDS LIST_DIRECTORIES true RELATIVE ${PROJECT_SOURCE_DIR}/${folder}
       ${PROJECT_SOURCE_DIR}/${folder}/*)
  foreach(entry ${entries})
    set(path ${PROJECT_SOURCE_DIR}/${folder}/${entry})
    if(entry IN_LIST ARG_EXCLUDE)
      continue()
    endif()
    if((IS_DIRECTORY ${path} AND NOT ARG_HEADERS_ONLY) OR (NOT IS_DIRECTORY ${path} AND entry MATCHES "\\.h$"))
      file(CREATE_LINK ${path} ${dir}/${folder}/${entry} SYMBOLIC)
    endif()
  endforeach()
  set(${out} ${dir} PARENT_SCOPE)
endfunction()

# act_header_root(out root header...): a root holding only the given headers (paths relative to the
# source dir), each at its path: what a layer exports on purpose to those who may not see the layer.
function(act_header_root out root)
  set(dir ${ACT_LAYER_INCLUDE_DIR}/${root})
  file(REMOVE_RECURSE ${dir})
  foreach(header ${ARGN})
    get_filename_component(parent ${dir}/${header} DIRECTORY)
    file(MAKE_DIRECTORY ${parent})
    file(CREATE_LINK ${PROJECT_SOURCE_DIR}/${header} ${dir}/${header} SYMBOLIC)
  endforeach()
  set(${out} ${dir} PARENT_SCOPE)
endfunction()

# The one public header the layers below the engine may include: the error vocabulary.
act_header_root(ACT_STATUS_INCLUDE_ROOT status engine/include/actengine/status.h)
set(ACT_STATUS_INCLUDE_ROOT ${ACT_STATUS_INCLUDE_ROOT}/engine/include)

# act_add_layer(name DIR dir | DIRS dir... ROOT folder [HEADERS_ONLY] [EXCLUDE entry...]
#               [PUBLIC_API] [DEPS ...]): one OBJECT library per architectural layer, holding every
# .cc file directly in the given folder(s). Its include root is made from ROOT (act_layer_root, with
# HEADERS_ONLY and EXCLUDE; EXCLUDEd .cc files are not built either), seen by the layer and by those that link it; a layer below the engine
# sees actengine/status.h alone, an engine layer (PUBLIC_API) all of engine/include. The layers are
# linked together into libactengine. Per-ISA kernel files get their instruction-set flags
# (act_set_isa_flags).
function(act_add_layer name)
  cmake_parse_arguments(ARG "HEADERS_ONLY;PUBLIC_API" "DIR;ROOT" "DIRS;DEPS;EXCLUDE" ${ARGN})
  set(sources)
  foreach(dir ${ARG_DIR} ${ARG_DIRS})
    file(GLOB dir_sources CONFIGURE_DEPENDS ${dir}/*.cc)
    foreach(src ${dir_sources})
      get_filename_component(src_name ${src} NAME)
      if(NOT src_name IN_LIST ARG_EXCLUDE)
        list(APPEND sources ${src})
      endif()
    endforeach()
  endforeach()
  set(root_options)
  if(ARG_HEADERS_ONLY)
    list(APPEND root_options HEADERS_ONLY)
  endif()
  act_layer_root(root ${name} ${ARG_ROOT} ${root_options} EXCLUDE ${ARG_EXCLUDE})
  add_library(${name} OBJECT ${sources})
  target_include_directories(${name} PUBLIC $<BUILD_INTERFACE:${root}>)
  if(ARG_PUBLIC_API)
    target_include_directories(${name} PUBLIC $<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}/engine/include>)
  else()
    target_include_directories(${name} PUBLIC $<BUILD_INTERFACE:${ACT_STATUS_INCLUDE_ROOT}>)
  endif()
  target_link_libraries(${name} PUBLIC ${ARG_DEPS})
  act_set_warnings(${name})
  act_set_isa_flags(${sources})
endfunction()

# act_set_isa_flags(source...): per-file instruction-set flags, chosen by the file name's suffix
# (the kernel naming grammar's ISA suffix: the level the code needs, kernels/common/isa.h):
#   *_avx2.cc        -mavx2 -mfma                                              (x86-64 targets)
#   *_avxvnni.cc     -mavx2 -mfma -mavxvnni                                    (x86-64 targets)
#   *_avx512.cc      -mavx2 -mfma -mavx512f -mavx512bw -mavx512vl              (x86-64 targets)
#   *_avx512vnni.cc  -mavx2 -mfma -mavx512f -mavx512bw -mavx512vl -mavx512vnni (x86-64 targets)
#   *_amx.cc         the avx512vnni flags and -mamx-tile -mamx-int8            (x86-64 targets)
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
    elseif(act_x86 AND src MATCHES "_avxvnni\\.cc$")
      set_source_files_properties(${src} PROPERTIES COMPILE_OPTIONS "-mavx2;-mfma;-mavxvnni")
    elseif(act_x86 AND src MATCHES "_avx512\\.cc$")
      set_source_files_properties(${src} PROPERTIES COMPILE_OPTIONS "-mavx2;-mfma;-mavx512f;-mavx512bw;-mavx512vl")
    elseif(act_x86 AND src MATCHES "_avx512vnni\\.cc$")
      set_source_files_properties(${src} PROPERTIES COMPILE_OPTIONS
        "-mavx2;-mfma;-mavx512f;-mavx512bw;-mavx512vl;-mavx512vnni")
    elseif(act_x86 AND src MATCHES "_amx\\.cc$")
      set_source_files_properties(${src} PROPERTIES COMPILE_OPTIONS
        "-mavx2;-mfma;-mavx512f;-mavx512bw;-mavx512vl;-mavx512vnni;-mamx-tile;-mamx-int8")
    elseif(act_arm64 AND src MATCHES "_neondot\\.cc$")
      set_source_files_properties(${src} PROPERTIES COMPILE_OPTIONS "-march=armv8.2-a+dotprod")
    endif()
  endforeach()
endfunction()

# The layers' headers the apps may include, exported on purpose (the apps otherwise see only the
# public headers, engine/include; cmake/check_layer_includes.py gets the same list):
#   weights/blob/file_util.h     atomic file writes, whole-file reads and checked JSON parsing: the
#                                apps write their reports, packages and recordings as the library does
#   weights/blob/file_kind.h     what kind of file a path is and which tool takes it: every tool's
#                                wrong-kind-of-file message
#   weights/import/safetensors.h the observation files (act_eval, act_bench --observations) are
#                                safetensors; it includes weights/blob/file_mapping.h and
#                                weights/blob/tensor_types.h, exported with it
#   engine/src/convert/observation_file.h  observation files (act_eval, act_bench --observations)
#   engine/media/media_io.h      image files and video through the module loaded on first use
#                                (act_drive's camera and recordings, act_eval's episodes)
# And act_bench_probes (bench/probes) exports bench_probes.h to act_bench.
set(ACT_PROBES_EXPORTED_HEADERS bench/probes/bench_probes.h)
set(ACT_APP_EXPORTED_HEADERS
  weights/blob/file_util.h
  weights/blob/file_kind.h
  weights/import/safetensors.h
  weights/blob/file_mapping.h
  weights/blob/tensor_types.h
  engine/src/convert/observation_file.h
  engine/media/media_io.h)
