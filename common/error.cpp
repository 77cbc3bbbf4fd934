#include "common/error.hpp"

#include <cstdio>
#include <cstdlib>

namespace st {

void check_failed(const char* expr, const char* file, int line) {
  std::fprintf(stderr, "shadowtile: internal check failed: %s (%s:%d)\n", expr, file, line);
  std::abort();
}

}  // namespace st
