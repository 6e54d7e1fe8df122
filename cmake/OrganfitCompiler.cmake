# Compiler settings shared by every target: warnings, ccache, sanitizers.

find_program(ORGANFIT_CCACHE ccache)
if(ORGANFIT_CCACHE AND NOT CMAKE_CXX_COMPILER_LAUNCHER)
  set(CMAKE_C_COMPILER_LAUNCHER ${ORGANFIT_CCACHE})
  set(CMAKE_CXX_COMPILER_LAUNCHER ${ORGANFIT_CCACHE})
endif()

add_library(organfit_warnings INTERFACE)
target_compile_options(organfit_warnings INTERFACE
  $<$<CXX_COMPILER_ID:GNU,Clang>:-Wall -Wextra -Wpedantic -Wshadow -Wnon-virtual-dtor>)

if(ORGANFIT_SANITIZE)
  add_compile_options(-fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined)
  add_link_options(-fsanitize=address,undefined)
endif()
