# client_core: the format-agnostic hierarchy and cut engine, node sources (local file, HTTP with
# libcurl), the asynchronous fetcher and the LRU caches. No OpenGL here (that is client_gl).
# Included by client/CMakeLists.txt; paths are relative to this file.
catpaq_library(client_core
  SOURCES
    ${CMAKE_CURRENT_LIST_DIR}/src/hierarchy.cpp
    ${CMAKE_CURRENT_LIST_DIR}/src/cut_engine.cpp
    ${CMAKE_CURRENT_LIST_DIR}/src/fetcher.cpp
    ${CMAKE_CURRENT_LIST_DIR}/src/fetcher_http.cpp
    ${CMAKE_CURRENT_LIST_DIR}/src/cache.cpp
  DEPS base common_codec catp CURL::libcurl TBB::tbb Threads::Threads)
target_include_directories(client_core PUBLIC ${CMAKE_CURRENT_LIST_DIR}/include)
