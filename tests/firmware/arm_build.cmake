# Cross-builds both node images from firmware/ (its own CMake project, see
# firmware/CMakeLists.txt), prints their flash/RAM use and fails if either does not fit its
# part. Run by ctest as firmware_arm_build:
#   cmake -DSOURCE_DIR=<repo>/firmware -DBINARY_DIR=<build>/firmware-arm -P arm_build.cmake
cmake_minimum_required(VERSION 3.25)

find_program(ARM_GCC arm-none-eabi-gcc)
find_program(ARM_SIZE arm-none-eabi-size)
if(NOT ARM_GCC OR NOT ARM_SIZE)
  message(FATAL_ERROR "arm-none-eabi-gcc/size not found: install gcc-arm-none-eabi (./setup.sh deps)")
endif()

# Nodes 2 and 3 as well (sensor_node_f103_node2/3.elf): the firmware-in-the-loop bus test
# puts three nodes on one bus.
execute_process(COMMAND ${CMAKE_COMMAND} -S ${SOURCE_DIR} -B ${BINARY_DIR} -DMOCAP_SENSOR_NODE_IDS=2,3
                RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "configuring the firmware failed")
endif()
execute_process(COMMAND ${CMAKE_COMMAND} --build ${BINARY_DIR} -j 2 RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "building the firmware failed")
endif()

# image | part | flash limit | RAM limit (the F407's 64 KiB CCM RAM is not used by the image)
set(images
  "f103/sensor_node/sensor_node_f103.elf|STM32F103C8|65536|20480"
  "f407/sink_node/sink_node_f407.elf|STM32F407VG|1048576|131072")
set(failed FALSE)
foreach(entry ${images})
  string(REPLACE "|" ";" fields "${entry}")
  list(GET fields 0 elf)
  list(GET fields 1 part)
  list(GET fields 2 flash_limit)
  list(GET fields 3 ram_limit)
  execute_process(COMMAND ${ARM_SIZE} ${BINARY_DIR}/${elf} OUTPUT_VARIABLE out RESULT_VARIABLE rc)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "arm-none-eabi-size failed on ${elf}")
  endif()
  # Berkeley format: header line, then "text data bss dec hex filename".
  string(REGEX MATCH "\n[ \t]*([0-9]+)[ \t]+([0-9]+)[ \t]+([0-9]+)" _ "${out}")
  set(text ${CMAKE_MATCH_1})
  set(data ${CMAKE_MATCH_2})
  set(bss ${CMAKE_MATCH_3})
  math(EXPR flash "${text} + ${data}")
  math(EXPR ram "${data} + ${bss}")
  math(EXPR flash_pct "100 * ${flash} / ${flash_limit}")
  math(EXPR ram_pct "100 * ${ram} / ${ram_limit}")
  message(STATUS "${part} ${elf}: flash ${flash} / ${flash_limit} B (${flash_pct}%), "
                 "RAM ${ram} / ${ram_limit} B (${ram_pct}%, stack reserve included)")
  if(flash GREATER flash_limit OR ram GREATER ram_limit)
    message(SEND_ERROR "${elf} does not fit the ${part}")
    set(failed TRUE)
  endif()
endforeach()
if(failed)
  message(FATAL_ERROR "an image does not fit its part")
endif()
