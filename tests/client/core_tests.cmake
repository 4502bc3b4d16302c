# client_core_tests: the hierarchy and cut engine (synthetic DAGs and a real CATP dataset, with
# crack checks), node sources and the fetcher (a local file, and HTTP against a small in-test
# server with fault injection), the LRU caches, and the format seam with a second, test-only
# format (box_format.h).
if(NOT TARGET client_core)
  return()
endif()
file(GLOB CLIENT_CORE_TEST_SOURCES CONFIGURE_DEPENDS ${CMAKE_CURRENT_LIST_DIR}/test_core_*.cpp)
catpaq_test(client_core_tests
  SOURCES ${CLIENT_CORE_TEST_SOURCES} ${CMAKE_CURRENT_LIST_DIR}/box_format.cpp
  DEPS client_core catp_client catp mesh common_codec base Threads::Threads)
# crack_check.h (the CATP crack test's welding and border count) lives with the catp tests.
target_include_directories(client_core_tests PRIVATE ${PROJECT_SOURCE_DIR}/tests/catp)
# Against the real server too, when it is part of the build.
if(TARGET server)
  target_link_libraries(client_core_tests PRIVATE server)
  target_include_directories(client_core_tests PRIVATE ${PROJECT_SOURCE_DIR}/server/include)
  target_compile_definitions(client_core_tests PRIVATE CATPAQ_HAVE_SERVER=1)
endif()
