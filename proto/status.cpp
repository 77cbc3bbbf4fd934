#include "proto/status.hpp"

namespace st::proto {

std::string to_string(const Status& s) {
  std::string out(to_string(s.code));
  if (!s.detail.empty()) {
    out += ": ";
    out += s.detail;
  }
  return out;
}

}  // namespace st::proto
