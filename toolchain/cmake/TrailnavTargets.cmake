# Compile settings shared by every trailnav target.

set(TRAILNAV_WARNINGS
  -Wall -Wextra -Wpedantic -Wconversion -Wsign-conversion -Wshadow
  -Wnon-virtual-dtor -Wold-style-cast -Wcast-align -Woverloaded-virtual
  -Wdouble-promotion -Wformat=2 -Wimplicit-fallthrough)

if(TRAILNAV_SANITIZER STREQUAL "address")
  set(TRAILNAV_SANITIZER_FLAGS -fsanitize=address,undefined -fno-omit-frame-pointer
                               -fno-sanitize-recover=undefined)
elseif(TRAILNAV_SANITIZER STREQUAL "thread")
  set(TRAILNAV_SANITIZER_FLAGS -fsanitize=thread -fno-omit-frame-pointer)
elseif(NOT TRAILNAV_SANITIZER STREQUAL "")
  message(FATAL_ERROR "TRAILNAV_SANITIZER must be empty, 'address' or 'thread', not '${TRAILNAV_SANITIZER}'")
endif()

# Applies the project's warnings (as errors unless TRAILNAV_WERROR is off) and
# the sanitizer flags to one of our own targets.
function(trailnav_configure_target target)
  target_compile_options(${target} PRIVATE ${TRAILNAV_WARNINGS})
  if(TRAILNAV_WERROR)
    target_compile_options(${target} PRIVATE -Werror)
  endif()
  if(TRAILNAV_SANITIZER_FLAGS)
    target_compile_options(${target} PRIVATE ${TRAILNAV_SANITIZER_FLAGS})
    target_link_options(${target} PUBLIC ${TRAILNAV_SANITIZER_FLAGS})
  endif()
endfunction()

# trailnav_add_library(<name> SOURCES ... DEPENDS ...): one static library per
# module, public headers under <module>/include.
function(trailnav_add_library name)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPENDS;PRIVATE_DEPENDS" ${ARGN})
  add_library(${name} STATIC ${ARG_SOURCES})
  target_include_directories(${name} PUBLIC ${CMAKE_CURRENT_SOURCE_DIR}/include)
  target_link_libraries(${name} PUBLIC ${ARG_DEPENDS} PRIVATE ${ARG_PRIVATE_DEPENDS})
  trailnav_configure_target(${name})
endfunction()

# trailnav_add_executable(<name> SOURCES ... DEPENDS ...)
function(trailnav_add_executable name)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPENDS" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE ${ARG_DEPENDS})
  trailnav_configure_target(${name})
endfunction()

# trailnav_add_test(<name> SOURCES ... DEPENDS ... LABEL <label> [TIMEOUT s]): a
# GoogleTest executable whose cases are registered with CTest one by one. Each
# executable carries exactly one label: its module (runtime, drivers, ...), or
# `slow` for long runs that CI leaves to the benchmarks job.
# SLOW <gtest filter>: the tests of the executable that match it carry
# `slow` instead (timeout 900 s), the others the module's label.
function(trailnav_add_test name)
  cmake_parse_arguments(ARG "" "TIMEOUT;LABEL;SLOW" "SOURCES;DEPENDS" ${ARGN})
  if(NOT ARG_LABEL)
    message(FATAL_ERROR "trailnav_add_test(${name}): LABEL is required")
  endif()
  # The ThreadSanitizer tree runs only the multi-threaded suites (the tsan
  # test preset's labels, CMakePresets.json): the others are defined there
  # but left out of its build and of CTest.
  set(single_threaded FALSE)
  if(TRAILNAV_SANITIZER STREQUAL "thread" AND NOT ARG_LABEL MATCHES "^(runtime|drivers|e2e|dds)$")
    set(single_threaded TRUE)
  endif()
  if(single_threaded)
    add_executable(${name} EXCLUDE_FROM_ALL ${ARG_SOURCES})
  else()
    add_executable(${name} ${ARG_SOURCES})
  endif()
  target_link_libraries(${name} PRIVATE ${ARG_DEPENDS} GTest::gtest GTest::gmock GTest::gtest_main)
  trailnav_configure_target(${name})
  if(single_threaded)
    return()
  endif()
  if(NOT ARG_TIMEOUT)
    set(ARG_TIMEOUT 120)
  endif()
  if(ARG_SLOW)
    gtest_discover_tests(${name}
      WORKING_DIRECTORY ${PROJECT_SOURCE_DIR}
      TEST_FILTER "-${ARG_SLOW}"
      PROPERTIES LABELS ${ARG_LABEL} TIMEOUT ${ARG_TIMEOUT}
      DISCOVERY_TIMEOUT 60)
    gtest_discover_tests(${name}
      WORKING_DIRECTORY ${PROJECT_SOURCE_DIR}
      TEST_FILTER "${ARG_SLOW}"
      PROPERTIES LABELS slow TIMEOUT 900
      DISCOVERY_TIMEOUT 60)
  else()
    gtest_discover_tests(${name}
      WORKING_DIRECTORY ${PROJECT_SOURCE_DIR}
      PROPERTIES LABELS ${ARG_LABEL} TIMEOUT ${ARG_TIMEOUT}
      DISCOVERY_TIMEOUT 60)
  endif()
endfunction()

# trailnav_add_benchmark(<name> SOURCES ... DEPENDS ...): a Google Benchmark
# executable, built by default and collected under the `bench` target. CTest
# never times it.
function(trailnav_add_benchmark name)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPENDS" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE ${ARG_DEPENDS} benchmark::benchmark)
  trailnav_configure_target(${name})
  if(NOT TARGET bench)
    add_custom_target(bench)
  endif()
  add_dependencies(bench ${name})
endfunction()
