// Validation of hand-made MH / MMH buffers: shared blocks (legal in MMH only), blocks of
// the wrong kind, pointers into another node's value word, padding and trailing words.
// Each buffer is written word by word so the case it tests is exactly the one named.
#include <gtest/gtest.h>

#include <cstring>

#include "tiles/core/encoding.hpp"
#include "common/error.hpp"
#include "tiles/core/mh_quadtree_format.hpp"

namespace st {
namespace mh_quadtree_validate_test {

using namespace mhq;

// Header + tree words; byte_size filled in. Shifts all zero.
std::vector<uint8_t> buffer(bool mmh, uint32_t levels, uint32_t node_count, const std::vector<uint32_t>& words) {
  std::vector<uint8_t> b(tree_offset(levels) + 4 * words.size(), 0);
  const uint32_t magic = mmh ? kMagicMmh : kMagicMh;
  std::memcpy(b.data() + kOffMagic, &magic, 4);
  b[kOffVersion] = uint8_t(kVersion);
  b[kOffLevels] = uint8_t(levels);
  b[kOffFlags] = mmh ? kFlagRelative : 0;
  std::memcpy(b.data() + kOffNodeCount, &node_count, 4);
  const uint32_t size = uint32_t(b.size());
  std::memcpy(b.data() + kOffByteSize, &size, 4);
  std::memcpy(b.data() + tree_offset(levels), words.data(), 4 * words.size());
  return b;
}

std::string error_of(bool mmh, const std::vector<uint8_t>& b) {
  try {
    if (mmh) open_mmh(b);
    else open_mh(b);
  } catch (const FormatError& e) {
    return e.what();
  }
  return "";
}

// Root 0.5 with empty children A (slot 0) and B (slot 1); both point at one block
// holding a leaf in slot 0, stored relative: 0.5 + 0.25.
std::vector<uint32_t> shared_words() {
  return {node_word(0x0A, 0, 2), float_bits(0.5f),   // root, block at word 2
          node_word(0x01, 0, 2), node_word(0x01, 0, 1),  // A -> word 4, B -> word 4
          float_bits(0.25f)};
}

TEST(MhQuadtreeValidate, SharedBlocksOpenInMmhOnly) {
  const auto mmh = buffer(true, 3, 4, shared_words());
  ASSERT_EQ(error_of(true, mmh), "");
  const auto ev = open_mmh(mmh);
  EXPECT_EQ(ev->depth(2, 0, 0), 0.75f);  // through A
  EXPECT_EQ(ev->depth(2, 2, 0), 0.75f);  // through B, the same leaf
  EXPECT_EQ(ev->depth(2, 1, 0), 0.5f);   // A has no slot 1: the root answers
  EXPECT_EQ(ev->depth(1, 1, 0), 0.5f);
  EXPECT_NE(error_of(false, buffer(false, 3, 4, shared_words())).find("reached twice"), std::string::npos);
  // The leaf counts once.
  EXPECT_NE(error_of(true, buffer(true, 3, 5, shared_words())).find("node_count"), std::string::npos);
}

TEST(MhQuadtreeValidate, ASharedBlockOfAnotherKindIsRejected) {
  auto w = shared_words();
  w[3] = node_word(0x02, 0, 1);  // B says its slot-0 child at word 4 is an empty node
  EXPECT_NE(error_of(true, buffer(true, 3, 4, w)).find("node at byte 36: overlaps another node of a different kind"),
            std::string::npos)
      << error_of(true, buffer(true, 3, 4, w));
}

TEST(MhQuadtreeValidate, APointerIntoAValueWordIsRejected) {
  // Root: slot 0 empty B (word 2), slot 1 inner C (words 3-4). B points at word 4, C's
  // value, as if a leaf were there; C's block is the leaf at word 5.
  const std::vector<uint32_t> w = {node_word(0x0E, 0, 2), float_bits(0.5f), node_word(0x01, 0, 2),
                                   node_word(0x01, 0, 2), float_bits(0.25f), float_bits(0.125f)};
  for (bool mmh : {false, true}) {
    const std::string e = error_of(mmh, buffer(mmh, 3, 5, w));
    EXPECT_NE(e.find("node at byte 36: overlaps another node"), std::string::npos) << e;
  }
}

TEST(MhQuadtreeValidate, PaddingMustBeZeroAndTrailingWordsAreRejected) {
  // Root block at word 3 (off 3): word 2 is padding.
  std::vector<uint32_t> w = {node_word(0x01, 0, 3), float_bits(0.5f), 0, float_bits(0.25f)};
  EXPECT_EQ(error_of(false, buffer(false, 2, 2, w)), "");
  w[2] = 7;
  EXPECT_NE(error_of(false, buffer(false, 2, 2, w)).find("padding at byte 28"), std::string::npos);
  w[2] = 0;
  w.push_back(0);
  EXPECT_NE(error_of(false, buffer(false, 2, 2, w)).find("trailing bytes"), std::string::npos);
}

TEST(MhQuadtreeValidate, ChildrenBelowTheFinestLevelAreRejected) {
  // levels = 2: the root's children are at the finest level and must be leaves.
  const std::vector<uint32_t> w = {node_word(0x02, 0, 2), float_bits(0.5f), node_word(0x01, 0, 1), float_bits(0.25f)};
  EXPECT_NE(error_of(false, buffer(false, 2, 3, w)).find("children below the finest level"), std::string::npos);
  // MMH: block Y (an empty node over a leaf) is reached at level 2 through B and again at
  // level 3 through A -> X, where its leaf would sit below the finest level (3).
  const std::vector<uint32_t> deep = {
      node_word(0x0A, 0, 2), float_bits(0.5f),  // root: slot 0 empty B (word 2), slot 1 empty A (word 3)
      node_word(0x02, 0, 3),                    // B: slot 0 empty -> word 5 (Y)
      node_word(0x02, 0, 1),                    // A: slot 0 empty -> word 4 (X)
      node_word(0x02, 0, 1),                    // X: slot 0 empty -> word 5 (Y again)
      node_word(0x01, 0, 1),                    // Y: slot 0 leaf -> word 6
      float_bits(0.25f)};
  const std::string e = error_of(true, buffer(true, 4, 6, deep));
  EXPECT_NE(e.find("node at byte 40: shared subtree reaches below the finest level"), std::string::npos) << e;
  // One level more and the same sharing is legal.
  EXPECT_EQ(error_of(true, buffer(true, 5, 6, deep)), "");
}

}  // namespace mh_quadtree_validate_test
}  // namespace st
