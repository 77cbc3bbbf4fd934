// Linked into every benchmark when SHADOWTILE_BENCH_OPT is set (bench/CMakeLists.txt).
// scripts/test compiles the benchmarks at a lower optimisation only to keep them compiling
// (CI never runs them), so a benchmark built that way says so before it prints figures
// that are not the optimised build's.
#include <cstdio>

namespace {

const bool kBenchOptNoted = [] {
  std::fprintf(stderr,
               "note: this benchmark was compiled with %s (SHADOWTILE_BENCH_OPT, a compile check): its "
               "figures are not the release build's; `cmake --preset release` rebuilds it optimised\n",
               SHADOWTILE_BENCH_OPT_TEXT);
  return true;
}();

}  // namespace
