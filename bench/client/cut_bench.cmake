# cut_bench: CutEngine::update per frame over a camera path on a ~100k-node synthetic hierarchy,
# incremental front against rebuilding the cut from the root in the same run. Needs only
# client_core (no GL). Included by bench/client/CMakeLists.txt when present.
if(TARGET client_core)
  add_executable(cut_bench ${CMAKE_CURRENT_LIST_DIR}/cut_bench.cpp)
  target_link_libraries(cut_bench PRIVATE client_core)
  catpaq_warnings(cut_bench)
endif()
