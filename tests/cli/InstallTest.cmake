# cmake -P script of the install.consumer test: install the build into PREFIX, then configure,
# build and run tests/cli/consumer against it. Variables: BUILD_DIR, PREFIX, WORK_DIR,
# CONSUMER_SOURCE, CXX_COMPILER, BUILD_TYPE; PYTHON (the interpreter, empty when the
# Python module is not built) and PYTHON_DIR (where the module is installed, relative to PREFIX).
cmake_minimum_required(VERSION 3.25)

# A fresh prefix each time, so that nothing from an earlier install can satisfy find_package. The
# consumer's build folder is kept: it rebuilds only what changed.
file(REMOVE_RECURSE "${PREFIX}")
execute_process(COMMAND "${CMAKE_COMMAND}" --install "${BUILD_DIR}" --prefix "${PREFIX}" --config "${BUILD_TYPE}"
                OUTPUT_QUIET COMMAND_ERROR_IS_FATAL ANY)
foreach(f lib/cmake/duplex/duplexConfig.cmake lib/cmake/duplex/duplexConfigVersion.cmake
          include/duplex/accel/TopLevel.h include/duplex/scenegraph/SceneTracer.h bin/duplex bin/duplex_demo
          share/duplex/examples/scenes/robot_cell.json)
  if(NOT EXISTS "${PREFIX}/${f}")
    message(FATAL_ERROR "install: ${PREFIX}/${f} is missing")
  endif()
endforeach()

# The installed demo finds its default scene under the prefix, from any working directory.
file(MAKE_DIRECTORY "${WORK_DIR}")
execute_process(COMMAND "${PREFIX}/bin/duplex_demo" --width 32 --height 18 --threads 2 --out "${WORK_DIR}/demo.png"
                WORKING_DIRECTORY "${WORK_DIR}/.." RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
string(FIND "${out}" "${PREFIX}/share/duplex/examples/scenes/robot_cell.json" at)
if(NOT rc EQUAL 0 OR at EQUAL -1 OR NOT EXISTS "${WORK_DIR}/demo.png")
  message(FATAL_ERROR "install: the installed demo did not render its default scene from the prefix (${rc}): ${out}${err}")
endif()

# The Python module, imported from the prefix alone (PYTHONPATH is the install folder, not the build's).
if(PYTHON)
  execute_process(COMMAND "${CMAKE_COMMAND}" -E env "PYTHONPATH=${PREFIX}/${PYTHON_DIR}" "${PYTHON}" -c
                          "import duplex, numpy; s = duplex.Scene(); o = s.add_mesh(numpy.eye(3), [[0, 1, 2]]); s.add_instance(o); s.commit(); h = s.cast_rays([0.2, 0.2, 1, -1, -1, -1]); assert h['instance_ids'] == 0, h; print(duplex.__file__)"
                  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0 OR NOT out MATCHES "^${PREFIX}/${PYTHON_DIR}/duplex")
    message(FATAL_ERROR "install: the Python module in ${PREFIX}/${PYTHON_DIR} does not import (${rc}): ${out}${err}")
  endif()
  message(STATUS "python module: ${out}")
endif()

execute_process(COMMAND "${CMAKE_COMMAND}" -S "${CONSUMER_SOURCE}" -B "${WORK_DIR}"
                        "-DCMAKE_PREFIX_PATH=${PREFIX}" "-DCMAKE_CXX_COMPILER=${CXX_COMPILER}"
                        "-DCMAKE_BUILD_TYPE=${BUILD_TYPE}"
                OUTPUT_QUIET COMMAND_ERROR_IS_FATAL ANY)
execute_process(COMMAND "${CMAKE_COMMAND}" --build "${WORK_DIR}" OUTPUT_QUIET COMMAND_ERROR_IS_FATAL ANY)
execute_process(COMMAND "${WORK_DIR}/duplex_consumer" RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
message(STATUS "consumer: ${out}${err}")
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "the installed-package consumer failed (${rc})")
endif()
