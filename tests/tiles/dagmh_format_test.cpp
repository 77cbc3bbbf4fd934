// DAG-MH format pins (tiles/core/DAGMH.md): field offsets and sizes of the header, the
// skip entries and chunk infos, and where an encoded buffer puts them.
#include <gtest/gtest.h>

#include <cstddef>

#include "tests/tiles/dagmh_fixtures.hpp"
#include "tiles/build/dagmh_encode.hpp"
#include "tiles/core/dagmh_format.hpp"

namespace st::dagmh {
namespace {

TEST(DagmhFormat, StructOffsetsArePinned) {
  EXPECT_EQ(sizeof(Header), 72u);
  EXPECT_EQ(offsetof(Header, magic), 0u);
  EXPECT_EQ(offsetof(Header, version), 4u);
  EXPECT_EQ(offsetof(Header, header_bytes), 8u);
  EXPECT_EQ(offsetof(Header, finest_level), 12u);
  EXPECT_EQ(offsetof(Header, skip_level), 16u);
  EXPECT_EQ(offsetof(Header, root_ref), 20u);
  EXPECT_EQ(offsetof(Header, node_words), 24u);
  EXPECT_EQ(offsetof(Header, treelet_count), 28u);
  EXPECT_EQ(offsetof(Header, value_count), 32u);
  EXPECT_EQ(offsetof(Header, chunk_count), 36u);
  EXPECT_EQ(offsetof(Header, multiplier_bytes), 40u);
  EXPECT_EQ(offsetof(Header, total_bytes), 44u);
  EXPECT_EQ(offsetof(Header, skip_offset), 48u);
  EXPECT_EQ(offsetof(Header, node_offset), 52u);
  EXPECT_EQ(offsetof(Header, treelet_offset), 56u);
  EXPECT_EQ(offsetof(Header, chunk_offset), 60u);
  EXPECT_EQ(offsetof(Header, multiplier_offset), 64u);
  EXPECT_EQ(offsetof(Header, dictionary_crc), 68u);
  EXPECT_EQ(sizeof(Cursor), 16u);
  EXPECT_EQ(offsetof(Cursor, ref), 0u);
  EXPECT_EQ(offsetof(Cursor, level), 4u);
  EXPECT_EQ(offsetof(Cursor, base), 8u);
  EXPECT_EQ(offsetof(Cursor, last), 12u);
  EXPECT_EQ(sizeof(ChunkInfo), 24u);
  EXPECT_EQ(offsetof(ChunkInfo, base), 0u);
  EXPECT_EQ(offsetof(ChunkInfo, mask), 4u);
  EXPECT_EQ(offsetof(ChunkInfo, c_l), 8u);
  EXPECT_EQ(offsetof(ChunkInfo, c_f), 12u);
  EXPECT_EQ(offsetof(ChunkInfo, bit_offset), 16u);
  EXPECT_EQ(offsetof(ChunkInfo, factor_bits), 20u);
  EXPECT_EQ(kTreeletBytes, 12u);
  EXPECT_EQ(kMagic, 0x484D4744u);
  EXPECT_EQ(kVersion, 1u);
  EXPECT_EQ(kVersionDictionary, 2u);
  // The pack dictionary (DAGMH.md "Dictionary").
  EXPECT_EQ(sizeof(DictHeader), 32u);
  EXPECT_EQ(offsetof(DictHeader, magic), 0u);
  EXPECT_EQ(offsetof(DictHeader, version), 4u);
  EXPECT_EQ(offsetof(DictHeader, header_bytes), 8u);
  EXPECT_EQ(offsetof(DictHeader, node_words), 12u);
  EXPECT_EQ(offsetof(DictHeader, treelet_count), 16u);
  EXPECT_EQ(offsetof(DictHeader, total_bytes), 20u);
  EXPECT_EQ(offsetof(DictHeader, node_offset), 24u);
  EXPECT_EQ(offsetof(DictHeader, treelet_offset), 28u);
  EXPECT_EQ(kDictMagic, 0x444D4744u);
  EXPECT_EQ(kDictVersion, 1u);
}

uint32_t u32_at(const std::vector<uint8_t>& b, size_t at) { return st::load_le<uint32_t>(b.data() + at); }

TEST(DagmhFormat, EncodedBufferHasTheDrawnLayout) {
  const Hierarchy h = dagmh_test::random_hierarchy(9, 3, 0.6, 0.5, dagmh_test::mixed_interval);
  EncodeStats st;
  const auto b = encode(h, &st);
  ASSERT_GE(b.size(), 72u);
  EXPECT_EQ(std::string(b.begin(), b.begin() + 4), "DGMH");
  EXPECT_EQ(u32_at(b, 4), 1u);
  EXPECT_EQ(u32_at(b, 8), 72u);
  EXPECT_EQ(u32_at(b, 12), 9u);
  EXPECT_EQ(u32_at(b, 16), st.skip_level);
  EXPECT_EQ(u32_at(b, 24) * 4ull, st.node_bytes);
  EXPECT_EQ(u32_at(b, 28) * 12ull, st.treelet_bytes);
  EXPECT_EQ(u32_at(b, 32), h.valued_count());
  EXPECT_EQ(u32_at(b, 36), (h.valued_count() + 31) / 32);
  EXPECT_EQ(u32_at(b, 40), st.multiplier_bytes);
  EXPECT_EQ(u32_at(b, 44), b.size());
  // Sections follow each other in the drawn order, 4-byte aligned.
  EXPECT_EQ(u32_at(b, 48), 72u);
  EXPECT_EQ(u32_at(b, 52), 72u + st.skip_bytes);
  EXPECT_EQ(u32_at(b, 56), u32_at(b, 52) + st.node_bytes);
  EXPECT_EQ(u32_at(b, 60), u32_at(b, 56) + st.treelet_bytes);
  EXPECT_EQ(u32_at(b, 64), u32_at(b, 60) + st.chunk_bytes);
  EXPECT_EQ(u32_at(b, 64) + st.multiplier_bytes, b.size());
  for (size_t f = 48; f <= 64; f += 4) EXPECT_EQ(u32_at(b, f) % 4, 0u);
  EXPECT_EQ(u32_at(b, 68), 0u);
  // The root is the first inner node (the highest) or treelet 0.
  EXPECT_TRUE(u32_at(b, 20) == kRefInner || u32_at(b, 20) == kRefTreelet);
  // Skip entry (0, 0) starts at the root's level-S node: its base is 0 or 1 (root value).
  Cursor c;
  std::memcpy(&c, b.data() + 72, sizeof(c));
  EXPECT_LE(c.level, st.skip_level);
  EXPECT_EQ(c.last, 0u);
}

TEST(DagmhFormat, ShallowHierarchyIsOneTreeletWithoutInnerNodes) {
  const Hierarchy h = dagmh_test::random_hierarchy(3, 8, 0.9, 0.5, dagmh_test::mixed_interval);
  EncodeStats st;
  const auto b = encode(h, &st);
  EXPECT_EQ(u32_at(b, 20), kRefTreelet);
  EXPECT_EQ(st.node_bytes, 0u);
  EXPECT_EQ(st.dag_treelets, 1u);
  // The treelet bitmap holds one bit per valued node, depth-first (§3.2).
  const uint32_t off = u32_at(b, 56);
  const uint32_t bits = uint32_t(__builtin_popcount(u32_at(b, off))) +
                        uint32_t(__builtin_popcount(u32_at(b, off + 4))) +
                        uint32_t(__builtin_popcount(u32_at(b, off + 8)));
  EXPECT_EQ(bits, h.valued_count());
}

}  // namespace
}  // namespace st::dagmh
