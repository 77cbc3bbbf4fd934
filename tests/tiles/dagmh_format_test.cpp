// DAG-MH format pins (tiles/core/DAGMH.md): field offsets and sizes of the header, the
// skip entries and chunk infos, and where an encoded buffer puts them.
#include <gtest/gtest.h>

#include <cstddef>

#include "tests/tiles/dagmh_fixtures.hpp"
#include "tiles/encode/dagmh_encode.hpp"
#include "tiles/core/dagmh_format.hpp"

namespace st::dagmh {
namespace {

TEST(DagmhFormat, StructOffsetsArePinned) {
  EXPECT_EQ(sizeof(Header), 32u);
  EXPECT_EQ(offsetof(Header, magic), 0u);
  EXPECT_EQ(offsetof(Header, version), 4u);
  EXPECT_EQ(offsetof(Header, finest_level), 8u);
  EXPECT_EQ(offsetof(Header, skip_level), 9u);
  EXPECT_EQ(offsetof(Header, flags), 10u);
  EXPECT_EQ(offsetof(Header, reserved), 11u);
  EXPECT_EQ(offsetof(Header, root_ref), 12u);
  EXPECT_EQ(offsetof(Header, node_words), 16u);
  EXPECT_EQ(offsetof(Header, treelet_count), 20u);
  EXPECT_EQ(offsetof(Header, value_count), 24u);
  EXPECT_EQ(offsetof(Header, dictionary_crc), 28u);
  EXPECT_EQ(sizeof(Cursor), 16u);
  EXPECT_EQ(offsetof(Cursor, ref), 0u);
  EXPECT_EQ(offsetof(Cursor, level), 4u);
  EXPECT_EQ(offsetof(Cursor, base), 8u);
  EXPECT_EQ(offsetof(Cursor, last), 12u);
  EXPECT_EQ(sizeof(ChunkInfo), 20u);
  EXPECT_EQ(offsetof(ChunkInfo, base), 0u);
  EXPECT_EQ(offsetof(ChunkInfo, mask), 4u);
  EXPECT_EQ(offsetof(ChunkInfo, c_l), 8u);
  EXPECT_EQ(offsetof(ChunkInfo, c_f), 12u);
  EXPECT_EQ(offsetof(ChunkInfo, packed), 16u);
  EXPECT_EQ(kBitOffsetBits, 27u);
  EXPECT_EQ(kRawFactorCode, 31u);
  EXPECT_EQ(pack_factor(5, 7), 5u | 7u << 27);
  EXPECT_EQ(pack_factor(0, kRawFactorBits), 31u << 27);
  EXPECT_EQ(kTreeletBytes, 12u);
  EXPECT_EQ(kMagic, 0x484D4744u);
  EXPECT_EQ(kVersion, 3u);
  EXPECT_EQ(kFlagDictionary, 1u);
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
  ASSERT_GE(b.size(), 32u);
  EXPECT_EQ(std::string(b.begin(), b.begin() + 4), "DGMH");
  EXPECT_EQ(u32_at(b, 4), 3u);
  EXPECT_EQ(b[8], 9u);
  EXPECT_EQ(b[9], st.skip_level);
  EXPECT_EQ(b[10], 0u);  // flags: no dictionary
  EXPECT_EQ(b[11], 0u);
  EXPECT_EQ(u32_at(b, 16) * 4ull, st.node_bytes);
  EXPECT_EQ(u32_at(b, 20) * 12ull, st.treelet_bytes);
  EXPECT_EQ(u32_at(b, 24), h.valued_count());
  EXPECT_EQ(u32_at(b, 28), 0u);
  // Sections follow each other in the drawn order from byte 32, their offsets implied by
  // the counts; the multipliers are the rest of the buffer.
  ASSERT_GT(st.skip_level, 0u);
  EXPECT_EQ(st.skip_bytes, 16u << (2 * st.skip_level));
  EXPECT_EQ(st.chunk_bytes, 20ull * ((h.valued_count() + 31) / 32));
  EXPECT_EQ(32u + st.skip_bytes + st.node_bytes + st.treelet_bytes + st.chunk_bytes + st.multiplier_bytes, b.size());
  const Sections s = sections_of(load_header(b.data()), b.size());
  EXPECT_EQ(s.skip, 32u);
  EXPECT_EQ(s.nodes, 32u + st.skip_bytes);
  EXPECT_EQ(s.treelets, s.nodes + st.node_bytes);
  EXPECT_EQ(s.chunks, s.treelets + st.treelet_bytes);
  EXPECT_EQ(s.multipliers, s.chunks + st.chunk_bytes);
  EXPECT_EQ(s.multipliers % 4, 0u);
  EXPECT_EQ(b.size() % 4, 0u);
  // The root is the first inner node (the highest) or treelet 0.
  EXPECT_TRUE(u32_at(b, 12) == kRefInner || u32_at(b, 12) == kRefTreelet);
  // Skip entry (0, 0) starts at the root's level-S node: its base is 0 or 1 (root value).
  Cursor c;
  std::memcpy(&c, b.data() + 32, sizeof(c));
  EXPECT_LE(c.level, st.skip_level);
  EXPECT_EQ(c.last, 0u);
}

TEST(DagmhFormat, ShallowHierarchyIsOneTreeletWithoutInnerNodes) {
  const Hierarchy h = dagmh_test::random_hierarchy(3, 8, 0.9, 0.5, dagmh_test::mixed_interval);
  EncodeStats st;
  const auto b = encode(h, &st);
  EXPECT_EQ(u32_at(b, 12), kRefTreelet);
  EXPECT_EQ(st.node_bytes, 0u);
  EXPECT_EQ(st.dag_treelets, 1u);
  // Skip level 0 stores no table (the root cursor is the header's root_ref): the
  // treelet follows the header.
  EXPECT_EQ(st.skip_level, 0u);
  EXPECT_EQ(st.skip_bytes, 0u);
  EXPECT_EQ(b.size(), 32u + 12u + st.chunk_bytes + st.multiplier_bytes);
  // The treelet bitmap holds one bit per valued node, depth-first (§3.2).
  const uint32_t off = uint32_t(sections_of(load_header(b.data()), b.size()).treelets);
  const uint32_t bits = uint32_t(__builtin_popcount(u32_at(b, off))) +
                        uint32_t(__builtin_popcount(u32_at(b, off + 4))) +
                        uint32_t(__builtin_popcount(u32_at(b, off + 8)));
  EXPECT_EQ(bits, h.valued_count());
}

}  // namespace
}  // namespace st::dagmh
