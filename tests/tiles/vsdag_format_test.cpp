// Voxel shadow DAG format (tiles/core/VSDAG.md): every header offset and constant pinned,
// one small buffer pinned byte for byte, the tree shape rule, and hostile buffers
// (truncated at every length, every byte flipped, references out of order) rejected with
// a FormatError naming the field, never read out of bounds.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "common/error.hpp"
#include "tests/tiles/interval_fields.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/encode/vsdag_encode.hpp"
#include "tiles/core/encoding.hpp"
#include "tiles/core/vsdag_evaluator.hpp"

namespace st::vsdag {
namespace {

TEST(VsdagFormat, HeaderOffsetsAndConstants) {
  EXPECT_EQ(sizeof(Header), 64u);
  EXPECT_EQ(offsetof(Header, magic), 0u);
  EXPECT_EQ(offsetof(Header, version), 4u);
  EXPECT_EQ(offsetof(Header, header_bytes), 8u);
  EXPECT_EQ(offsetof(Header, xy_bits), 12u);
  EXPECT_EQ(offsetof(Header, z_bits), 16u);
  EXPECT_EQ(offsetof(Header, grid_xy_bits), 20u);
  EXPECT_EQ(offsetof(Header, grid_z_bits), 24u);
  EXPECT_EQ(offsetof(Header, inner_levels), 28u);
  EXPECT_EQ(offsetof(Header, leaf_count), 32u);
  EXPECT_EQ(offsetof(Header, node_words), 36u);
  EXPECT_EQ(offsetof(Header, leaf_offset), 40u);
  EXPECT_EQ(offsetof(Header, grid_offset), 44u);
  EXPECT_EQ(offsetof(Header, node_offset), 48u);
  EXPECT_EQ(offsetof(Header, total_bytes), 52u);
  EXPECT_EQ(offsetof(Header, reserved0), 56u);
  EXPECT_EQ(offsetof(Header, reserved1), 60u);
  EXPECT_EQ(kMagic, 0x47445356u);
  EXPECT_EQ(std::memcmp(&kMagic, "VSDG", 4), 0);
  EXPECT_EQ(kVersion, 1u);
  EXPECT_EQ(kShadow, 0u);
  EXPECT_EQ(kLit, 1u);
  EXPECT_EQ(kMixed, 2u);
  EXPECT_EQ(kGridMaxCells, 64u);
  EXPECT_EQ(uint32_t(Encoding::vsdag), 3u);
  EXPECT_EQ(leaf_bit(5, 2), 21u);  // row-major 8x8: y * 8 + x
}

TEST(VsdagFormat, ShapeSplitsTheLongerAxisFirstAndFoldsTheTopIntoTheGrid) {
  const Shape s = Shape::of(10, 16);  // 7 xy splits, 13 depth splits above the z-nodes
  EXPECT_EQ(s.grid_xy_bits, 0u);
  EXPECT_EQ(s.grid_z_bits, 6u);  // the 6 depth-only splits: 64 cells
  ASSERT_EQ(s.levels, 7u);
  for (uint32_t i = 0; i < s.levels; ++i) {
    EXPECT_EQ(s.split[i], kSplitXy | kSplitZ);
    EXPECT_EQ(s.xy_shift[i], 9 - i);
    EXPECT_EQ(s.z_shift[i], 9 - i);
  }
  const Shape t = Shape::of(12, 4);  // 9 xy, 1 depth split
  EXPECT_EQ(t.grid_xy_bits, 3u);     // 4^3 = 64 cells
  EXPECT_EQ(t.grid_z_bits, 0u);
  EXPECT_EQ(t.levels, 6u);
  EXPECT_EQ(t.split[5], kSplitXy | kSplitZ);
  EXPECT_EQ(t.split[0], kSplitXy);
  const Shape u = Shape::of(1, 3);  // a 2x2 tile padded to one 8x8 leaf
  EXPECT_EQ(u.padded_xy_bits, 3u);
  EXPECT_EQ(u.levels, 0u);
  EXPECT_EQ(u.grid_cells(), 1u);
}

TEST(VsdagFormat, ReceiverSlabs) {
  EXPECT_EQ(receiver_slab(-1e-30f, 8), kReceiverLit);
  EXPECT_EQ(receiver_slab(-0.0f, 8), 0);
  EXPECT_EQ(receiver_slab(0.5f, 8), 128);
  EXPECT_EQ(receiver_slab(std::nextafter(0.5f, 0.0f), 8), 127);
  EXPECT_EQ(receiver_slab(1.0f, 8), 255);
  EXPECT_EQ(receiver_slab(1.5f, 8), kReceiverShadowed);
  EXPECT_EQ(receiver_slab(NAN, 8), kReceiverShadowed);
}

std::vector<uint8_t> encode_field(const IntervalTile& t, uint32_t z) {
  return encode_vsdag(build_hierarchy(t), VsdagOptions{z});
}

TEST(VsdagFormat, SmallestBufferByteForByte) {
  // 8x8 texels of [0.25, 0.5] at 8 slabs: transition 4, one grid cell pointing at one
  // z-node whose slabs 0-3 are lit and 4-7 shadowed; no leaves.
  const std::vector<uint8_t> b = encode_field(fields::constant_field(8, Interval{0.25f, 0.5f}), 3);
  const uint32_t want[] = {kMagic, 1, 64, 3, 3, 0, 0, 0, /*leaves*/ 0, /*node words*/ 1, 64, 64, 68, 72, 0, 0,
                           /*grid*/ 0x80000000u, /*z-node*/ 0x55u};
  ASSERT_EQ(b.size(), sizeof want);
  EXPECT_EQ(std::memcmp(b.data(), want, sizeof want), 0);
  const VsdagEvaluator ev(b);
  EXPECT_FLOAT_EQ(ev.depth(3, 2, 2), std::nextafter(0.5f, 0.0f));
  EXPECT_TRUE(ev.lit_voxel(3, 7, 7, 0.49f));
  EXPECT_FALSE(ev.lit_voxel(3, 7, 7, 0.5f));
}

void expect_rejected(const std::vector<uint8_t>& b, const std::string& what) {
  try {
    open_vsdag(b);
    ADD_FAILURE() << "accepted: " << what;
  } catch (const FormatError& e) {
    EXPECT_NE(std::string(e.what()).find("vsdag: "), std::string::npos) << e.what();
  }
}

std::vector<uint8_t> sample_buffer() {
  return encode_field(fields::scene_field(fields::small_test_scale() ? 32 : 64, 3), 8);
}

TEST(VsdagFormat, TruncatedAndExtendedBuffersAreRejected) {
  const std::vector<uint8_t> b = sample_buffer();
  ASSERT_GT(b.size(), 500u);
  for (size_t n = 0; n < b.size(); ++n) expect_rejected(std::vector<uint8_t>(b.begin(), b.begin() + n), "truncated");
  std::vector<uint8_t> longer = b;
  longer.push_back(0);
  expect_rejected(longer, "one trailing byte");
}

TEST(VsdagFormat, EveryByteFlippedIsRejectedOrAnswersInBounds) {
  const std::vector<uint8_t> b = sample_buffer();
  size_t rejected = 0;
  for (size_t i = 0; i < b.size(); i += (fields::small_test_scale() ? 7 : 1)) {
    std::vector<uint8_t> c = b;
    c[i] ^= uint8_t(1u << (i % 8));
    std::unique_ptr<Evaluator> ev;
    try {
      ev = open_vsdag(c);
    } catch (const FormatError&) {
      ++rejected;
      continue;
    }
    // Accepted (e.g. a leaf bit): every lookup stays inside the buffer (ASan checks).
    const uint64_t side = uint64_t(1) << ev->finest_level();
    for (uint64_t y = 0; y < side; y += 5)
      for (uint64_t x = 0; x < side; x += 3) {
        (void)ev->depth(ev->finest_level(), x, y);
        (void)ev->pcf(ev->finest_level(), x, y, 9, float(x) / float(side));
      }
  }
  EXPECT_GT(rejected, 0u);
}

TEST(VsdagFormat, StructuralViolationsNameTheirField) {
  const std::vector<uint8_t> b = sample_buffer();
  Header h;
  std::memcpy(&h, b.data(), sizeof h);
  ASSERT_GT(h.node_words, 4u);
  auto word = [&](std::vector<uint8_t>& c, uint64_t at) -> uint32_t* { return reinterpret_cast<uint32_t*>(c.data() + at); };
  auto expect_message = [&](std::vector<uint8_t> c, const char* field) {
    try {
      open_vsdag(c);
      ADD_FAILURE() << "accepted a bad " << field;
    } catch (const FormatError& e) {
      EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
    }
  };
  {
    std::vector<uint8_t> c = b;
    *word(c, offsetof(Header, z_bits)) = 21;
    expect_message(c, "z_bits");
  }
  {
    std::vector<uint8_t> c = b;
    *word(c, offsetof(Header, reserved1)) = 1;
    expect_message(c, "reserved1");
  }
  {
    // The last node is the top of a grid cell's subtree; a grid cell pointing at word 1
    // (inside the first node, or at a node of the wrong level) is refused.
    std::vector<uint8_t> c = b;
    const uint32_t cells = 1u << (2 * h.grid_xy_bits + h.grid_z_bits);
    for (uint32_t k = 0; k < cells; ++k) {
      uint32_t* g = word(c, h.grid_offset + 4ull * k);
      if ((*g >> kStateShift) == kMixed) {
        *g = (kMixed << kStateShift) | (h.node_words + 5);
        break;
      }
    }
    expect_message(c, "reference");
  }
  {
    std::vector<uint8_t> c = b;
    uint32_t* g = word(c, h.grid_offset);
    *g = 3u << kStateShift;
    expect_message(c, "grid cell");
  }
}

}  // namespace
}  // namespace st::vsdag
