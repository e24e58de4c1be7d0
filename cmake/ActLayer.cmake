# act_add_layer(name DIR dir [DEPS ...]): one OBJECT library per architectural layer, holding every
# .cc file directly in that folder. The layers are linked together into libactengine.
function(act_add_layer name)
  cmake_parse_arguments(ARG "" "DIR" "DEPS" ${ARGN})
  file(GLOB sources CONFIGURE_DEPENDS ${ARG_DIR}/*.cc)
  if(NOT sources)  # a layer still being written: keep the build configurable
    set(sources ${CMAKE_CURRENT_BINARY_DIR}/${name}_empty.cc)
    file(WRITE ${sources} "// no sources yet\n")
  endif()
  add_library(${name} OBJECT ${sources})
  target_include_directories(${name} PUBLIC
    $<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}>
    $<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}/engine/include>)
  target_link_libraries(${name} PUBLIC ${ARG_DEPS})
  act_set_warnings(${name})
endfunction()
