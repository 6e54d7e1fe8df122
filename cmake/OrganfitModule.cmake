# organfit_module(NAME
#                 [SOURCES src...]          library sources (headers are under include/)
#                 [PUBLIC_DEPS targets...]  what users of this module also see
#                 [PRIVATE_DEPS targets...] what only the implementation needs
#                 [TEST_DEPS targets...])   extra libraries for the module's tests
#
# Makes library organfit_<NAME> (alias organfit::<NAME>) with public headers in
# include/organfit/<NAME>/, and, when test/*.cpp exist, one GoogleTest executable
# <NAME>_tests whose tests ctest discovers one by one.
function(organfit_module NAME)
  cmake_parse_arguments(ARG "" "" "SOURCES;PUBLIC_DEPS;PRIVATE_DEPS;TEST_DEPS" ${ARGN})
  set(target organfit_${NAME})
  add_library(${target} STATIC ${ARG_SOURCES})
  add_library(organfit::${NAME} ALIAS ${target})
  target_include_directories(${target} PUBLIC ${CMAKE_CURRENT_SOURCE_DIR}/include)
  target_link_libraries(${target} PUBLIC ${ARG_PUBLIC_DEPS} PRIVATE ${ARG_PRIVATE_DEPS} organfit_warnings)

  file(GLOB test_sources CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/test/*.cpp)
  if(ORGANFIT_BUILD_TESTS AND test_sources)
    add_executable(${NAME}_tests ${test_sources})
    target_link_libraries(${NAME}_tests PRIVATE ${target} ${ARG_TEST_DEPS} GTest::gtest_main organfit_warnings)
    if(TARGET organfit_sanitizer_defaults)
      target_link_libraries(${NAME}_tests PRIVATE organfit_sanitizer_defaults)
    endif()
    target_compile_definitions(${NAME}_tests PRIVATE
      ORGANFIT_SOURCE_DIR="${PROJECT_SOURCE_DIR}"
      ORGANFIT_SHARED_DATA_DIR="${ORGANFIT_SHARED_DATA_DIR}")
    gtest_discover_tests(${NAME}_tests TEST_PREFIX "${NAME}." DISCOVERY_TIMEOUT 60
                         PROPERTIES LABELS ${NAME} ENVIRONMENT "${ORGANFIT_TEST_ENV}")
  endif()
endfunction()
