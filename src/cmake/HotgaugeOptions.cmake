# Per-target settings shared by every hotgauge target (style.md §9: no global flags).
set(CMAKE_EXPORT_COMPILE_COMMANDS ON)

function(hotgauge_target_options target)
  target_compile_features(${target} PUBLIC cxx_std_20)
  set_target_properties(${target} PROPERTIES CXX_EXTENSIONS OFF)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic -Wshadow
                                           -Wnon-virtual-dtor -Wconversion -Wno-sign-conversion)
  if(HOTGAUGE_FUZZ AND NOT HOTGAUGE_FUZZ_SANITIZE)
    # The volume build (make fuzz): libFuzzer's coverage instrumentation alone, optimised, for
    # executions per second; what it finds is replayed in the sanitizer build below.
    target_compile_options(${target} PUBLIC -O2 -gline-tables-only -fsanitize=fuzzer-no-link)
  elseif(HOTGAUGE_FUZZ)
    # libFuzzer's coverage instrumentation without its main (the harnesses link -fsanitize=fuzzer,
    # tests/fuzz/CMakeLists.txt) and the sanitizers, so that every finding is a crash with a stack.
    # -gline-tables-only: file:line in the stacks of findings, for 15 % less build time than -g.
    target_compile_options(${target} PUBLIC -O1 -gline-tables-only
                                            -fsanitize=fuzzer-no-link,address,undefined
                                            -fno-omit-frame-pointer -fno-sanitize-recover=undefined)
    target_link_options(${target} PUBLIC -fsanitize=address,undefined)
  elseif(HOTGAUGE_SANITIZE)
    # -O1: sanitized tests run several times faster than at -O0, and build faster than at -O2.
    target_compile_options(${target} PUBLIC -O1 -fsanitize=address,undefined
                                            -fno-omit-frame-pointer -fno-sanitize-recover=undefined)
    target_link_options(${target} PUBLIC -fsanitize=address,undefined)
  endif()
endfunction()

# hotgauge_module(NAME SOURCES ... DEPS ...): src/<name>/ -> library hotgauge_<name>.
function(hotgauge_module name)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS" ${ARGN})
  add_library(hotgauge_${name} STATIC ${ARG_SOURCES})
  add_library(hotgauge::${name} ALIAS hotgauge_${name})
  target_include_directories(hotgauge_${name} PUBLIC ${PROJECT_SOURCE_DIR}/include)
  target_link_libraries(hotgauge_${name} PUBLIC ${ARG_DEPS})
  hotgauge_target_options(hotgauge_${name})
endfunction()
