// DAG-MH hostile input: truncation at every length, trailing bytes, random bit flips and
// targeted corruptions give st::FormatError naming the field, or (for flips the format
// cannot see, e.g. in a stored value) a buffer whose lookups still stay in bounds. Run
// under ASan in the asan preset, so an out-of-bounds read fails the test.
#include <gtest/gtest.h>

#include <string>

#include "tests/tiles/dagmh_fixtures.hpp"
#include "tests/tiles/interval_fields.hpp"
#include "tiles/core/dagmh_format.hpp"
#include "common/error.hpp"

namespace st {
namespace {

using dagmh_test::random_hierarchy;

std::vector<uint8_t> small_buffer() {
  return encode_dagmh(random_hierarchy(7, 21, 0.55, 0.5, dagmh_test::mixed_interval));
}

std::string open_error(const std::vector<uint8_t>& b) {
  try {
    open_dagmh(b);
  } catch (const FormatError& e) {
    return e.what();
  }
  return "";
}

// Exercises every texel of every level and some PCF kernels (the ASan build checks the
// reads); returns a checksum so the work is not optimised away.
double exercise(const Evaluator& e) {
  double sum = 0;
  for (uint32_t l = 0; l <= e.finest_level(); ++l) {
    const uint64_t side = uint64_t(1) << l;
    for (uint64_t y = 0; y < side; ++y)
      for (uint64_t x = 0; x < side; ++x) sum += double(e.depth(l, x, y) == e.depth(l, x, y));
  }
  for (uint32_t r = 1; r <= 9; r += 4) sum += e.pcf(e.finest_level(), 3, 5, r, 0.5f);
  return sum;
}

TEST(DagmhHostile, EveryTruncationIsRejected) {
  const auto b = small_buffer();
  ASSERT_EQ(open_error(b), "");
  for (size_t n = 0; n < b.size(); ++n) {
    std::vector<uint8_t> cut(b.begin(), b.begin() + long(n));
    ASSERT_NE(open_error(cut), "") << "accepted a truncation to " << n << " of " << b.size() << " bytes";
  }
  auto longer = b;
  longer.push_back(0);
  EXPECT_NE(open_error(longer).find("multipliers at byte"), std::string::npos) << open_error(longer);
  longer.insert(longer.end(), {0, 0, 0});  // whole words of trailing zeros, too
  EXPECT_NE(open_error(longer).find("(no trailing bytes)"), std::string::npos) << open_error(longer);
}

TEST(DagmhHostile, RandomBitFlipsAreRejectedOrHarmless) {
  const auto b = small_buffer();
  fields::Rng rng(77);
  const int trials = fields::small_test_scale() ? 400 : 3000;
  int rejected = 0, accepted = 0;
  for (int t = 0; t < trials; ++t) {
    auto bad = b;
    const uint32_t flips = 1 + rng.below(3);
    for (uint32_t f = 0; f < flips; ++f) bad[rng.below(uint32_t(bad.size()))] ^= uint8_t(1u << rng.below(8));
    std::unique_ptr<Evaluator> e;
    try {
      e = open_dagmh(bad);
    } catch (const FormatError&) {
      ++rejected;
      continue;
    }
    ++accepted;
    EXPECT_GT(exercise(*e), 0.0);
  }
  EXPECT_GT(rejected, 0);
  EXPECT_GT(accepted, 0);  // flips in values are invisible to validation, and harmless
}

// Targeted corruptions name the field at fault.
TEST(DagmhHostile, CorruptionsNameTheField) {
  using namespace dagmh;
  const auto b = small_buffer();
  const Header h = load_header(b.data());
  const Sections s = sections_of(h, b.size());
  ASSERT_GT(h.node_words, 0u) << "the test buffer needs inner nodes";
  auto with = [&](size_t at, uint32_t v) {
    auto c = b;
    st::store_le<uint32_t>(c.data() + at, v);
    return open_error(c);
  };
  auto with_byte = [&](size_t at, uint8_t v) {
    auto c = b;
    c[at] = v;
    return open_error(c);
  };
  EXPECT_NE(with(0, 0x12345678).find("magic at byte 0"), std::string::npos);
  EXPECT_NE(with(4, 4).find("version at byte 4"), std::string::npos);
  // Tiles of the layout before version 3 are refused, naming their version.
  EXPECT_NE(with(4, 1).find("version at byte 4: is 1: a DAG-MH tile of the layout before version 3"), std::string::npos);
  EXPECT_NE(with(4, 2).find("version at byte 4: is 2"), std::string::npos);
  EXPECT_NE(with_byte(9, 7).find("skip_level"), std::string::npos);
  EXPECT_NE(with_byte(10, 2).find("flags at byte 10"), std::string::npos);
  EXPECT_NE(with_byte(10, 1).find("flags at byte 10: the tile references a pack dictionary"), std::string::npos);
  EXPECT_NE(with_byte(11, 1).find("reserved at byte 11"), std::string::npos);
  EXPECT_NE(with(28, 5).find("dictionary_crc at byte 28"), std::string::npos);
  // Counts that need more bytes than the buffer has, or leave a ragged multiplier section.
  EXPECT_NE(with(16, h.node_words + (1u << 20)).find("sections at byte"), std::string::npos);
  EXPECT_NE(with(16, h.node_words + 1), "");
  EXPECT_NE(with(24, h.value_count + 32 * 1000).find("sections"), std::string::npos);
  EXPECT_NE(with(12, kRefInner | 1).find("root_ref"), std::string::npos);
  const uint32_t root_flags = st::load_le<uint32_t>(b.data() + s.nodes);
  EXPECT_NE(with(s.nodes, root_flags | 0x200).find("node flags"), std::string::npos);
  // The root's first child: pointing backwards (at itself) or out of range.
  const bool first_is_treelet = (root_flags >> (kNodeTreeletShift + std::countr_zero(root_flags & 0xF))) & 1;
  EXPECT_NE(with(s.nodes + 4, first_is_treelet ? h.treelet_count : 0).find("node child reference"),
            std::string::npos);
  const uint32_t offset0 = st::load_le<uint32_t>(b.data() + s.nodes + 8);
  EXPECT_NE(with(s.nodes + 8, offset0 + 1).find("node value offset"), std::string::npos);
  if (h.skip_level > 0) {
    const uint32_t base = st::load_le<uint32_t>(b.data() + s.skip + 8);
    EXPECT_NE(with(s.skip + 8, base + 1).find("skip entry"), std::string::npos);
  }
  const uint32_t packed = st::load_le<uint32_t>(b.data() + s.chunks + 16);
  EXPECT_NE(with(s.chunks + 16, (packed & kBitOffsetMask) | 25u << 27)
                .find("chunk factor code at byte " + std::to_string(s.chunks + 16)),
            std::string::npos);
  EXPECT_NE(with(s.chunks + 16, (packed & ~kBitOffsetMask) | uint32_t(s.end - s.multipliers) * 8)
                .find("chunk bit_offset"),
            std::string::npos);
  EXPECT_NE(with(s.treelets + 8, 1u << 31).find("treelet"), std::string::npos);
}

}  // namespace
}  // namespace st
