// check_unity_clash.py's fixture: with b.cpp, exactly four clashes (helper, Row,
// kLimit, count); every other name is either not file-local or not shared.
#include <cstdint>
#include <vector>

namespace fx {
namespace {

using Bytes = std::vector<uint8_t>;  // the same alias in b.cpp: no clash
struct Row {
  int a;
};
int helper(int x) { return x + 1; }

}  // namespace

constexpr int kLimit = 6;
static int count = 0;
inline constexpr int kShared = 1;  // inline: one entity, no clash
int exported(int x) { return x; }  // external linkage: the linker's business
const char* text = "a";  // a pointer to const: external too (b.cpp has one)
const char* const kName = "a";  // a const pointer: file-local, only here

namespace a_only {
namespace {
int twice(int x) { return 2 * x; }  // b.cpp's twice is in another namespace
}  // namespace
}  // namespace a_only

struct Widget {
  static int make();  // a member, not a namespace-scope name
};
int Widget::make() {
  static int local = 0;  // a function's local
  return ++local;
}

}  // namespace fx
