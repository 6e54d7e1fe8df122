# Compiler settings shared by every target: warnings, ccache, sanitizers.

find_program(ORGANFIT_CCACHE ccache)
if(ORGANFIT_CCACHE AND NOT CMAKE_CXX_COMPILER_LAUNCHER)
  set(CMAKE_C_COMPILER_LAUNCHER ${ORGANFIT_CCACHE})
  set(CMAKE_CXX_COMPILER_LAUNCHER ${ORGANFIT_CCACHE})
endif()

add_library(organfit_warnings INTERFACE)
target_compile_options(organfit_warnings INTERFACE
  $<$<CXX_COMPILER_ID:GNU,Clang>:-Wall -Wextra -Wpedantic -Wshadow -Wnon-virtual-dtor>)

# ASan + UBSan. Every UBSan finding is fatal, except pointer-overflow, which is made
# recoverable so that tests/sanitizers/ubsan.supp can suppress the one finding inside
# ITK's own headers (see that file); the tests run with that suppression list.
if(ORGANFIT_SANITIZE)
  add_compile_options(-fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined
                      -fsanitize-recover=pointer-overflow)
  add_link_options(-fsanitize=address,undefined)
  # Default options and suppressions, linked directly into every test binary and the app
  # (an OBJECT library's objects reach only targets that link it directly).
  add_library(organfit_sanitizer_defaults OBJECT ${PROJECT_SOURCE_DIR}/tests/sanitizers/sanitizer_defaults.cpp)
  target_compile_definitions(organfit_sanitizer_defaults PRIVATE
    ORGANFIT_UBSAN_SUPPRESSIONS="${PROJECT_SOURCE_DIR}/tests/sanitizers/ubsan.supp")
endif()

# libFuzzer (clang only): every organfit library instrumented for coverage, with ASan and
# UBSan; the fuzz targets in tests/fuzz/ link libFuzzer's main.
if(ORGANFIT_FUZZ)
  if(NOT CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
    message(FATAL_ERROR "ORGANFIT_FUZZ needs clang (cmake -DCMAKE_CXX_COMPILER=clang++ -DCMAKE_C_COMPILER=clang)")
  endif()
  add_compile_options(-fsanitize=fuzzer-no-link,address,undefined -fno-omit-frame-pointer)
  add_link_options(-fsanitize=address,undefined)
endif()
