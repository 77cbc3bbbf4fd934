#include "tiles/core/resolution.hpp"

#include "common/error.hpp"
#include "tiles/core/interval.hpp"

namespace st {

uint32_t parse_resolution(const std::string& text) {
  std::string s = text;
  uint64_t mult = 1;
  if (!s.empty() && (s.back() == 'k' || s.back() == 'K')) mult = 1024, s.pop_back();
  else if (!s.empty() && (s.back() == 'm' || s.back() == 'M')) mult = 1024 * 1024, s.pop_back();
  uint64_t n = 0;
  size_t used = 0;
  try {
    n = std::stoull(s, &used);
  } catch (...) {
    used = 0;
  }
  if (s.empty() || used != s.size() || s[0] == '-')
    throw Error("--resolution: '" + text + "' is not a number like 4096, 16k or 1m");
  n *= mult;
  if (!is_power_of_two(n)) throw Error("--resolution: " + text + " is not a power of two");
  uint32_t level = log2_exact(n);
  if (level > kMaxLevel) throw Error("--resolution: " + text + " exceeds the maximum 1m (2^20)");
  return level;
}

}  // namespace st
