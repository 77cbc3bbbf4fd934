// check_unity_clash.py's fixture (see a.cpp).
#include <cstdint>
#include <vector>

namespace fx {
namespace {

using Bytes = std::vector<uint8_t>;
struct Row;  // a declaration defines nothing; the definition below does
struct Row {
  float b;
};
static const char* helper(const char* s) { return s; }  // another signature: still a clash

}  // namespace

const int kLimit = 7;
static int count = 1;
inline constexpr int kShared = 1;

namespace b_only {
namespace {
int twice(int x) { return x + x; }
}  // namespace
}  // namespace b_only

/* int commented_out(); */ const char* text = "namespace { int in_a_string; }";

}  // namespace fx
