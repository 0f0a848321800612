# Runs the bus-load table program and compares its output with the block of docs/protocol.md
# between "<!-- busload-table:begin -->" and "<!-- busload-table:end -->".
# Usage: cmake -DPROGRAM=... -DDOC=... -P check_doc_table.cmake
execute_process(COMMAND ${PROGRAM} OUTPUT_VARIABLE generated RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "${PROGRAM} failed with ${rc}")
endif()
file(READ ${DOC} doc)
string(FIND "${doc}" "<!-- busload-table:begin -->\n" begin)
string(FIND "${doc}" "<!-- busload-table:end -->" end)
if(begin EQUAL -1 OR end EQUAL -1)
  message(FATAL_ERROR "${DOC} has no busload-table markers")
endif()
string(LENGTH "<!-- busload-table:begin -->\n" marker_len)
math(EXPR begin "${begin} + ${marker_len}")
math(EXPR len "${end} - ${begin}")
string(SUBSTRING "${doc}" ${begin} ${len} documented)
if(NOT documented STREQUAL generated)
  message(FATAL_ERROR "docs table differs from the program output; regenerate it with\n"
                      "  ${PROGRAM}\nExpected:\n${generated}")
endif()
