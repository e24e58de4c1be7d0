# cmake -DBUILD_DIR=... -DSOURCE_DIR=... -DWORK_DIR=... -DLIBDIR=... -DBLOB=... -DCHECKPOINT=... -P run_consumer_test.cmake
# Installs the built project into a fresh prefix, builds test/consumer against it with
# find_package(actengine COMPONENTS vision), and runs the shared- and the static-linked consumers:
# running BLOB, and converting CHECKPOINT (a LeRobot checkpoint folder) to FP32 and INT8.
file(REMOVE_RECURSE ${WORK_DIR})
function(run)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "command failed (${rc}): ${ARGN}\n${out}\n${err}")
  endif()
  message(STATUS "${out}")
endfunction()
run(${CMAKE_COMMAND} --install ${BUILD_DIR} --prefix ${WORK_DIR}/prefix)
run(${CMAKE_COMMAND} -S ${SOURCE_DIR}/test/consumer -B ${WORK_DIR}/build -DCMAKE_PREFIX_PATH=${WORK_DIR}/prefix
    -DCMAKE_BUILD_TYPE=Release)
run(${CMAKE_COMMAND} --build ${WORK_DIR}/build)
set(ENV{LD_LIBRARY_PATH} ${WORK_DIR}/prefix/${LIBDIR}:$ENV{LD_LIBRARY_PATH})
run(${WORK_DIR}/build/consumer ${BLOB})
run(${WORK_DIR}/build/consumer_static ${BLOB})
file(MAKE_DIRECTORY ${WORK_DIR}/convert ${WORK_DIR}/convert_static)
run(${WORK_DIR}/build/consumer_convert ${CHECKPOINT} ${WORK_DIR}/convert)
run(${WORK_DIR}/build/consumer_convert_static ${CHECKPOINT} ${WORK_DIR}/convert_static)
