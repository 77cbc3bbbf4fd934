# Synthetic inputs shared by the tests and the benchmarks, never linked into the product:
# the interval fields (tests/tiles/interval_fields.hpp) that tiles_tests and
# bench_construction, bench_dagmh and bench_mh_quadtree build their maps from.
add_library(shadowtile_interval_fields STATIC ${CMAKE_CURRENT_LIST_DIR}/tiles/interval_fields.cpp)
target_link_libraries(shadowtile_interval_fields PUBLIC shadowtile::tiles_core PRIVATE shadowtile_warnings)
