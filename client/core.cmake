# client_core: the format-agnostic hierarchy and cut engine, node sources (local file, HTTP with
# libcurl), the asynchronous fetcher, the LRU caches and the format interface (format.h). No
# OpenGL here (that is client_gl), and no format: those are plug-ins (client/catp/).
# Included by client/CMakeLists.txt; paths are relative to this file.
catpaq_library(client_core
  SOURCES
    ${CMAKE_CURRENT_LIST_DIR}/src/hierarchy.cpp
    ${CMAKE_CURRENT_LIST_DIR}/src/cut_engine.cpp
    ${CMAKE_CURRENT_LIST_DIR}/src/fetcher.cpp
    ${CMAKE_CURRENT_LIST_DIR}/src/fetcher_http.cpp
    ${CMAKE_CURRENT_LIST_DIR}/src/cache.cpp
    ${CMAKE_CURRENT_LIST_DIR}/src/format.cpp
  DEPS base common_codec mesh CURL::libcurl TBB::tbb Threads::Threads)
target_include_directories(client_core PUBLIC ${CMAKE_CURRENT_LIST_DIR}/include)
