// Plane tiles (tiles/core/PLANES.md): blocks of a tile's finest texels answered by one
// plane each, decoded with integer arithmetic. Pinned here: the rounding of the fixed-point
// depth (to the nearest binary32, ties to even), the byte layout, the fit on real open
// meshes (every texel of every pack within a fresh trace), and hostile buffers refused;
// the packed form a pack stores them in (plane_pack.hpp) likewise.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <tuple>

#include "common/bytes.hpp"
#include "common/error.hpp"
#include "interval_fields.hpp"
#include "tiles/bake/map_build.hpp"
#include "tiles/bake/raster_bounds.hpp"
#include "scene/scene.hpp"
#include "tiles/encode/encode.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/encode/plane_fit.hpp"
#include "tiles/core/encoding.hpp"
#include "tiles/core/pack_evaluator.hpp"
#include "tiles/core/pack_format.hpp"
#include "tiles/core/plane_pack.hpp"
#include "tiles/core/plane_tile.hpp"

namespace st {
namespace plane_tiles_test {

namespace fs = std::filesystem;
using namespace planes;

constexpr const char* kModels = "/usr/share/assimp/models/";

// The exact value v 2^-60 rounded once to binary32 (long double holds v exactly).
float reference_round(int64_t v) {
  if (v <= 0) return 0.0f;
  if (v >= kOne) return 1.0f;
  return float(std::ldexp((long double)v, -int(kFracBits)));
}

TEST(PlaneFormat, FixedPointDepthIsTheNearestFloatTiesToEven) {
  std::mt19937_64 rng(7);
  for (int i = 0; i < 200000; ++i) {
    const int64_t v = int64_t(rng() >> (4 + rng() % 60));
    ASSERT_EQ(plane_fixed_to_float(v), reference_round(v)) << v;
    ASSERT_EQ(std::bit_cast<uint32_t>(plane_fixed_to_float_cpu(v)), std::bit_cast<uint32_t>(reference_round(v))) << v;
  }
  // Exact ties between two floats round to the even one, both ways.
  const int64_t one_and_half_ulp = (int64_t(1) << 59) + (int64_t(3) << 35);  // 0.5 + 1.5 ulp(0.5)
  EXPECT_EQ(plane_fixed_to_float(one_and_half_ulp), reference_round(one_and_half_ulp));
  EXPECT_EQ(plane_fixed_to_float((int64_t(1) << 59) + (int64_t(1) << 35)), 0.5f);  // 0.5 + ulp/2: to 0.5 (even)
  EXPECT_EQ(plane_fixed_to_float(kOne - 1), 1.0f);  // carries into the next binade
  EXPECT_EQ(plane_fixed_to_float(0), 0.0f);
  EXPECT_EQ(plane_fixed_to_float(-5), 0.0f);
  for (const int64_t v : {int64_t(0), int64_t(-5), INT64_MIN, kOne - 1, kOne, kOne + 12345, INT64_MAX, int64_t(1)})
    EXPECT_EQ(std::bit_cast<uint32_t>(plane_fixed_to_float_cpu(v)), std::bit_cast<uint32_t>(plane_fixed_to_float(v))) << v;
  EXPECT_EQ(plane_fixed_to_float(kOne + 12345), 1.0f);
  EXPECT_EQ(plane_fixed_to_float(1), 0x1p-60f);
  EXPECT_EQ(plane_fixed_to_float(int64_t(1) << 40), 0x1p-20f);
  // In every binade: exact ties after an even and an odd significand, one below and one
  // above them, the largest significand (its rounding carries into the next binade), and
  // every value of the binades kept exactly.
  for (int p = 0; p < int(kFracBits); ++p) {
    const int k = p - 23;
    for (const uint64_t m : {uint64_t(1) << 23, (uint64_t(1) << 23) + 1, (uint64_t(1) << 24) - 1, uint64_t(0xABCDEF)}) {
      if (k <= 0) {
        const int64_t v = int64_t(m >> (23 - p));
        ASSERT_EQ(plane_fixed_to_float(v), reference_round(v)) << v;
        ASSERT_EQ(std::bit_cast<uint32_t>(plane_fixed_to_float_cpu(v)), std::bit_cast<uint32_t>(reference_round(v))) << v;
        continue;
      }
      const uint64_t half = uint64_t(1) << (k - 1);
      for (const uint64_t rem : {uint64_t(0), half - 1, half, half + 1, (uint64_t(1) << k) - 1}) {
        const int64_t v = int64_t((m << k) | rem);
        ASSERT_EQ(plane_fixed_to_float(v), reference_round(v)) << v;
        ASSERT_EQ(std::bit_cast<uint32_t>(plane_fixed_to_float_cpu(v)), std::bit_cast<uint32_t>(reference_round(v))) << v;
      }
    }
  }
}

// Both pinned layouts below end alike: a labelled block of two planes (its palette, then
// labels 0, 1, 0, 1 in each byte) and the inner bytes. Appends those to `want`, checks the
// written tile `b` against it and returns the tile's view.
PlaneTileView expect_labelled_tail(const std::vector<uint8_t>& b, std::vector<uint8_t>& want,
                                   const std::vector<uint8_t>& palette, const std::vector<uint8_t>& inner) {
  want.insert(want.end(), palette.begin(), palette.end());
  want.insert(want.end(), 16, uint8_t(0x44));  // labels 0, 1, 0, 1 in each byte
  want.insert(want.end(), inner.begin(), inner.end());
  EXPECT_EQ(b, want);
  return validate_plane_tile(b);
}

TEST(PlaneFormat, LayoutIsPinned) {
  static_assert(kHeaderSize == 24 && kEntrySize == 24 && kRecordSize == 8 && kLabelSize == 24);
  static_assert(kOffMagic == 0 && kOffVersion == 4 && kOffLevels == 6 && kOffFlags == 7);
  static_assert(kOffPlaneCount == 8 && kOffByteSize == 12 && kOffTableCount == 16 && kOffLabelCount == 20);
  static_assert(kOffA == 0 && kOffB == 8 && kOffC == 16);
  static_assert(kOffStart == 0 && kOffShift == 4 && kOffKind == 5 && kOffIndex == 6 && kOffLabelBits == 8);
  static_assert(kKindPlane == 0 && kKindLabels == 1 && kLabelShift == 3 && kPalette == 4);
  static_assert(kMagic == 0x4E505453u && kVersion == 3 && kVersionNarrow == 2 && kFracBits == 60);
  static_assert(kKindWide == 2 && kWidePalette == 8 && kWideSlots == 2 && kOffWideBits == 16 && kOffWidePad == 40);
  // Tile of finest level 4 (16x16): an 8x8 block at (8, 0) and a 4x4 block at (0, 8) on one
  // plane (one table entry), and a labelled 8x8 block at (8, 8) whose odd columns take a
  // second plane.
  Plane p;
  p.start = 64;  // (8, 0)
  p.shift = 3;
  p.a = 0x0102030405060708;
  p.b = -2;
  p.c = 3;
  Plane p2 = p;
  p2.start = 128;  // (0, 8)
  p2.shift = 2;
  p2.a = p.a + 2 * 8 + 3 * 8;  // the same plane at (0, 8)
  LabelBlock lb;
  lb.start = 192;  // (8, 8)
  Plane at88 = p;
  at88.a = p.a + 3 * 8;  // the same plane at (8, 8)
  Plane q;
  q.shift = 3;
  q.a = 1000;
  q.b = 5;
  q.c = -7;
  lb.palette = {at88, q};
  for (uint32_t i = 0; i < 64; ++i) lb.label[i] = uint8_t(i % 2);
  const std::vector<uint8_t> inner{1, 2, 3, 4};
  const std::vector<uint8_t> b = wrap_planes({p, p2}, 4, inner, {lb});
  std::vector<uint8_t> want{'S', 'T', 'P', 'N', 2, 0, 5, 0,  // magic, version 2, levels, flags
                            3, 0, 0, 0, 124, 0, 0, 0,        // 3 blocks, byte size 24 + 48 + 24 + 24 + 4
                            2, 0, 0, 0, 1, 0, 0, 0};         // 2 planes, 1 labelled block
  auto le64 = [&](uint64_t v) {
    for (int k = 0; k < 8; ++k) want.push_back(uint8_t(v >> (8 * k)));
  };
  le64(0x0102030405060708 + 16);  // plane 0: a at (0, 0) = a - b 8
  le64(uint64_t(-2));
  le64(3);
  le64(1000 - 5 * 8 + 7 * 8);  // plane 1: a at (0, 0)
  le64(5);
  le64(uint64_t(-7));
  const std::vector<uint8_t> blocks{64, 0, 0, 0, 3, 0, 0, 0,    // start 64, shift 3, plane, index 0
                                    128, 0, 0, 0, 2, 0, 0, 0,   // start 128, shift 2, plane, index 0
                                    192, 0, 0, 0, 3, 1, 0, 0};  // start 192, shift 3, labelled, block 0
  want.insert(want.end(), blocks.begin(), blocks.end());
  // The labelled block's palette: unused entries repeat the last.
  const PlaneTileView v = expect_labelled_tail(b, want, {0, 0, 1, 0, 1, 0, 1, 0}, inner);
  EXPECT_EQ(v.finest_level, 4u);
  EXPECT_EQ(v.table_count, 2u);
  EXPECT_EQ(v.label_count, 1u);
  EXPECT_EQ(v.find(8, 0), 0);   // morton 64 = (8, 0): the block's corner
  EXPECT_EQ(v.find(15, 7), 0);  // its far corner
  EXPECT_EQ(v.find(7, 0), -1);
  EXPECT_EQ(v.find(3, 11), 1);
  EXPECT_EQ(v.find(4, 8), -1);
  EXPECT_EQ(v.find(9, 8), 2);
  EXPECT_EQ(v.plane(0).fixed(2, 1), 0x0102030405060708 - 4 + 3);
  EXPECT_EQ(v.plane(1).a, p2.a);
  EXPECT_EQ(v.plane_at(2, 8, 9).a, at88.a);  // even column: plane 0
  EXPECT_EQ(v.plane_at(2, 9, 9).a, 1000);    // odd column: plane 1 at the block's corner
  EXPECT_EQ(v.plane_at(2, 9, 9).fixed(1, 1), 1000 + 5 - 7);

  // The packed form of the same tile (plane_pack.hpp): the header and table as they were,
  // then the quadtree of block kinds, indices, palettes, one-bit labels, zeros, the inner.
  std::vector<uint8_t> packed_want(want.begin(), want.begin() + 24 + 48);
  packed_want[3] = 'Q';
  const std::vector<uint8_t> packed_planes{
      0x61, 0x02, 0x03,  // kinds: split | empty, plane, split | plane, empty, empty, empty | labelled
      0, 0,              // the two plane blocks' table indices (one byte: 2 planes)
      0x54, 0x03,        // palette classes 0, 1, 1, 1; labels use entries 0 and 1
      0, 1,              // its distinct planes
      0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA};  // one bit a texel: odd columns entry 1
  packed_want.insert(packed_want.end(), packed_planes.begin(), packed_planes.end());
  packed_want.resize(want.size() - inner.size(), 0);
  packed_want.insert(packed_want.end(), inner.begin(), inner.end());
  const std::vector<uint8_t> packed = pack_plane_tile(b, nullptr, false);
  EXPECT_EQ(packed, packed_want);
  EXPECT_TRUE(is_packed_plane_tile(packed));
  EXPECT_EQ(packed_plane_tile_features(packed), uint32_t(kFeaturePackedPlaneTiles));
  EXPECT_FALSE(is_plane_buffer(packed));
  std::vector<uint8_t> back = packed;
  unpack_plane_tile(back);
  EXPECT_EQ(back, b);
  EXPECT_TRUE(pack_plane_tile(packed).empty()) << "only a valid STPN tile packs";
  // With predicted labels ("STPL"): the labels alternate across the two planes, which no
  // prediction beats (each mode misses 32 texels, ties to mode 0): the same bytes, magic L.
  std::vector<uint8_t> predicted_want = packed_want;
  predicted_want[3] = 'L';
  EXPECT_EQ(pack_plane_tile(b), predicted_want);
  EXPECT_EQ(packed_plane_tile_features(predicted_want), uint32_t(kFeaturePackedPlaneTiles | kFeaturePredictedPlaneLabels));
  // A version 2 tile needs no wide_plane_blocks, in any form.
  EXPECT_EQ(plane_tile_features(b), 0u);
  EXPECT_EQ(plane_tile_features(predicted_want), uint32_t(kFeaturePackedPlaneTiles | kFeaturePredictedPlaneLabels));
  back = predicted_want;
  unpack_plane_tile(back);
  EXPECT_EQ(back, b);
}

// A wide labelled block (version 3, plane_format.hpp): 5 planes, label i mod 5 at texel i,
// two slots, then a labelled block of two planes in the third slot. Every byte of the STPN
// tile and of its packed forms is pinned; wide-block fields that are not the writer's are
// refused by name.
TEST(PlaneFormat, WideLabelledBlocksArePinnedAndChecked) {
  LabelBlock wide, narrow;
  wide.start = 0;      // (0, 0)
  narrow.start = 192;  // (8, 8)
  for (int64_t k = 0; k < 5; ++k) {
    Plane q;
    q.shift = 3;
    q.a = 100 * k, q.b = k, q.c = -k;  // at the corner (0, 0): the table's a
    wide.palette.push_back(q);
  }
  for (uint32_t i = 0; i < 64; ++i) wide.label[i] = uint8_t(i % 5), narrow.label[i] = uint8_t(i % 2);
  for (size_t k : {4, 1}) {
    Plane q = wide.palette[k];
    q.a += 8 * q.b + 8 * q.c;  // at (8, 8)
    narrow.palette.push_back(q);
  }
  const std::vector<uint8_t> inner{1, 2, 3, 4};
  const std::vector<uint8_t> b = wrap_planes({}, 4, inner, {wide, narrow});
  std::vector<uint8_t> want{'S', 'T', 'P', 'N', 3, 0, 5, 0,  // magic, version 3, levels, flags
                            2, 0, 0, 0, 236, 0, 0, 0,        // 2 blocks, byte size 24 + 120 + 16 + 72 + 4
                            5, 0, 0, 0, 3, 0, 0, 0};         // 5 planes, 3 label slots
  for (int64_t k = 0; k < 5; ++k)
    for (int64_t v : {100 * k, k, -k})
      for (int n = 0; n < 8; ++n) want.push_back(uint8_t(uint64_t(v) >> (8 * n)));
  const std::vector<uint8_t> blocks{0, 0, 0, 0, 3, 2, 0, 0,     // start 0, shift 3, wide, slot 0
                                    192, 0, 0, 0, 3, 1, 2, 0};  // start 192, shift 3, labelled, slot 2
  want.insert(want.end(), blocks.begin(), blocks.end());
  const std::vector<uint8_t> wide_bytes{
      0,    0,    1,    0,    2,    0,    3,    0,    4, 0, 4, 0, 4, 0, 4, 0,  // palette, unused entries repeat the last
      0x4A, 0x29, 0xA5, 0x94, 0x52, 0x4A, 0x29, 0xA5,                          // label bit 0 of texels 0..63
      0x8C, 0x31, 0xC6, 0x18, 0x63, 0x8C, 0x31, 0xC6,                          // bit 1
      0x10, 0x42, 0x08, 0x21, 0x84, 0x10, 0x42, 0x08,                          // bit 2
      0,    0,    0,    0,    0,    0,    0,    0};                            // padding
  want.insert(want.end(), wide_bytes.begin(), wide_bytes.end());
  const PlaneTileView v = expect_labelled_tail(b, want, {4, 0, 1, 0, 1, 0, 1, 0}, inner);  // the narrow block
  EXPECT_EQ(v.label_count, 3u);
  for (uint32_t i = 0; i < 64; ++i) EXPECT_EQ(v.plane_at(0, i % 8, i / 8).b, int64_t(i % 5)) << "texel " << i;
  EXPECT_EQ(v.plane_at(0, 7, 7).fixed(7, 7), 100 * 3 + 3 * 7 - 3 * 7);  // texel 63: plane 3
  EXPECT_EQ(v.plane_at(1, 8, 9).b, 4);
  EXPECT_EQ(v.plane_at(1, 9, 9).a, 100 + 8 - 8);  // odd column: plane 1 at the block's corner
  // Refused: a wide block in a version 2 tile, its padding, its slot, the slot count, its palette.
  auto refused = [](std::vector<uint8_t> bad, size_t at, uint8_t value, const char* what) {
    bad[at] = value;
    try {
      validate_plane_tile(bad);
      ADD_FAILURE() << "accepted: " << what;
    } catch (const FormatError& e) {
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
    }
  };
  const size_t records = 24 + 120, slots = records + 16;
  refused(b, kOffVersion, 2, "unknown kind 2 in a version 2 tile");
  refused(b, slots + 40, 1, "padding at byte 200: not zero");
  refused(b, records + 14, 1, "labelled blocks not in order");
  refused(b, kOffLabelCount, 2, "past the 2 label slots");
  refused(b, slots + 2 * 7, 5, "palette at byte 174: plane index >= 5");
  // Packed: no plane block indices; the wide block's palette bytes (0, 0x80), its 8 entries
  // and 24 label bytes as stored; the labelled block as before (plane_pack.hpp).
  std::vector<uint8_t> packed_want(want.begin(), want.begin() + 24 + 120);
  packed_want[3] = 'Q';
  const std::vector<uint8_t> packed_parts{
      0x0D, 0x03,                     // kinds: split, labelled, empty, empty | labelled
      0x00, 0x80, 0x54, 0x03,         // palettes: wide; classes 0, 1, 1, 1 using entries 0 and 1
      0, 1, 2, 3, 4, 4, 4, 4, 4, 1};  // the wide block's entries, the labelled block's distinct planes
  packed_want.insert(packed_want.end(), packed_parts.begin(), packed_parts.end());
  packed_want.insert(packed_want.end(), wide_bytes.begin() + 16, wide_bytes.begin() + 40);
  packed_want.insert(packed_want.end(), 8, uint8_t(0xAA));  // one bit a texel: odd columns entry 1
  packed_want.resize(want.size() - inner.size(), 0);
  packed_want.insert(packed_want.end(), inner.begin(), inner.end());
  EXPECT_EQ(pack_plane_tile(b, nullptr, false), packed_want);
  std::vector<uint8_t> predicted_want = packed_want;  // plane 1 is least everywhere: mode 0 ties the others
  predicted_want[3] = 'L';
  EXPECT_EQ(pack_plane_tile(b), predicted_want);
  // Version 3 in every form: a pack holding it declares wide_plane_blocks (pack_format.hpp).
  EXPECT_EQ(plane_tile_features(b), uint32_t(kFeatureWidePlaneBlocks));
  EXPECT_EQ(plane_tile_features(packed_want), uint32_t(kFeaturePackedPlaneTiles | kFeatureWidePlaneBlocks));
  EXPECT_EQ(plane_tile_features(predicted_want),
            uint32_t(kFeaturePackedPlaneTiles | kFeaturePredictedPlaneLabels | kFeatureWidePlaneBlocks));
  EXPECT_EQ(plane_tile_features(inner), 0u);
  for (const std::vector<uint8_t>& p : {packed_want, predicted_want}) {
    std::vector<uint8_t> back = p;
    unpack_plane_tile(back);
    EXPECT_EQ(back, b);
    auto refused_packed = [&](size_t at, uint8_t value, const char* what) {
      std::vector<uint8_t> bad = p;
      bad[at] = value;
      try {
        unpack_plane_tile(bad);
        ADD_FAILURE() << "unpacked: " << what;
      } catch (const FormatError& e) {
        EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
      }
    };
    const size_t palettes = 24 + 120 + 2;
    refused_packed(palettes, 1, "labelled block 0 classes at byte 146: not zero in a wide block");
    refused_packed(palettes + 1, 0x81, "2 labelled blocks take 2 slots, label_count says 3");  // not wide
    refused_packed(kOffLabelCount, 2, "2 labelled blocks take 3 slots, label_count says 2");
  }
}

// Predicted labels (plane_pack.hpp, "STPL"): two labelled 8x8 blocks where a rising plane
// A crosses a flat one; each texel's label is the lower plane there (ties to entry 0), the
// first block's last texel excepted. Every packed byte is pinned, and forms that are not
// the writer's (another mode, the all-predicted flag dropped, mode 3, a stray bit) are
// refused by name.
TEST(PlaneFormat, PredictedLabelsArePinnedAndCanonical) {
  auto flat = [](int64_t a) {
    Plane p;
    p.shift = 3;
    p.a = a;
    return p;
  };
  Plane a0 = flat(1000), a8 = flat(1080);  // A = 1000 + 10 x at the tile's (0, 0) and (8, 0)
  a0.b = a8.b = 10;
  LabelBlock first, second;
  first.start = 0;
  first.palette = {a0, flat(1040)};  // B: A is lower at x < 4, equal at 4
  second.start = 64;
  second.palette = {a8, flat(1120)};  // C: A is lower at x - 8 < 4, equal at 4
  for (uint32_t i = 0; i < 64; ++i) first.label[i] = second.label[i] = uint8_t(i % 8 > 4);
  first.label[63] = 0;  // one texel the prediction misses
  const std::vector<uint8_t> inner{1, 2, 3, 4};
  const std::vector<uint8_t> stpn = wrap_planes({}, 4, inner, {first, second});
  const size_t table_end = kHeaderSize + 3 * kEntrySize;
  ASSERT_EQ(load_le<uint32_t>(stpn.data() + kOffTableCount), 3u) << "A, B, C";
  std::vector<uint8_t> want(stpn.begin(), stpn.begin() + long(table_end));
  want[3] = 'L';
  const std::vector<uint8_t> packed_planes{
      0x3D, 0x00,              // kinds: split, labelled, labelled, empty | empty
      0x54, 0x13, 0x54, 0x53,  // classes 0, 1, 1, 1; entries 0 and 1 used, mode 1 (least), all predicted (0x40)
      0, 1, 0, 2,              // their distinct planes: A, B and A, C
      0, 0, 0, 0, 0, 0, 0, 0x80};  // the first block's residual: texel 63 only
  want.insert(want.end(), packed_planes.begin(), packed_planes.end());
  want.resize(stpn.size() - inner.size(), 0);
  want.insert(want.end(), inner.begin(), inner.end());
  const std::vector<uint8_t> packed = pack_plane_tile(stpn);
  ASSERT_EQ(packed, want);
  std::vector<uint8_t> back = packed;
  unpack_plane_tile(back);
  EXPECT_EQ(back, stpn);
  // The STPQ form stores the one-bit labels themselves.
  const std::vector<uint8_t> plain = pack_plane_tile(stpn, nullptr, false);
  EXPECT_EQ(plain[table_end + 3], 0x03);
  EXPECT_EQ(plain[table_end + 5], 0x03);
  back = plain;
  unpack_plane_tile(back);
  EXPECT_EQ(back, stpn);
  auto refused = [&](size_t at, std::vector<uint8_t> values, const char* why) {
    std::vector<uint8_t> bad = packed;
    std::copy(values.begin(), values.end(), bad.begin() + long(table_end + at));
    try {
      unpack_plane_tile(bad);
      ADD_FAILURE() << "byte " << at << " = " << int(values[0]) << " unpacked";
    } catch (const FormatError& e) {
      EXPECT_NE(std::string(e.what()).find(why), std::string::npos) << e.what();
    }
  };
  // The first block's own labels stored plainly (mode 0): they unpack, but mode 1 predicts more.
  std::vector<uint8_t> mode0{0x03, 0x54, 0x53, 0, 1, 0, 2};
  mode0.insert(mode0.end(), 7, uint8_t(0xE0));
  mode0.push_back(0x60);
  refused(3, mode0, "is not the one that predicts most");
  refused(5, {0x13}, "all predicted, not flagged so");  // the flag dropped: 8 zero bytes read
  refused(3, {0x33}, "prediction");                     // mode 3
  refused(3, {0x93}, "prediction");                     // bit 7
  refused(3, {0x11}, "prediction");                     // one entry used, with a mode
  refused(5, {0x03 | 0x40}, "prediction");              // all predicted without a mode
  std::vector<uint8_t> bad = plain;
  bad[table_end + 3] = 0x13;  // a mode in an STPQ tile
  EXPECT_THROW(unpack_plane_tile(bad), FormatError);

  // An MH inner buffer (a constant tile: its root a leaf): STPL leaves out the fields its
  // plane tile implies (magic, version, levels, byte_size: zeros) and names its kind in
  // header byte 7 (1 MH, 2 MMH); node_count, flags and the tree stay.
  const std::vector<uint8_t> mh{'S', 'T', 'M', 'H', 1, 0, 5, 1,  // magic, version 1, levels 5, root leaf
                                1, 0, 0, 0, 28, 0, 0, 0,         // 1 node, 28 bytes
                                0, 0, 0, 0, 0, 0, 0, 0,          // level shifts, padding
                                0, 0, 0x80, 0x3F};               // the leaf: 1.0f
  std::vector<uint8_t> with_mh = wrap_planes({}, 4, mh, {first, second});
  const std::vector<uint8_t> packed_mh = pack_plane_tile(with_mh);
  std::vector<uint8_t> want_mh = want;
  want_mh.resize(want.size() - inner.size());
  want_mh[kOffFlags] = 1;
  want_mh.insert(want_mh.end(), {0, 0, 0, 0, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0, 0, 0});
  want_mh.insert(want_mh.end(), mh.begin() + 16, mh.end());
  store_le<uint32_t>(want_mh.data() + kOffByteSize, uint32_t(with_mh.size()));
  EXPECT_EQ(packed_mh, want_mh);
  back = packed_mh;
  unpack_plane_tile(back);
  EXPECT_EQ(back, with_mh);
  EXPECT_EQ(pack_plane_tile(with_mh, nullptr, false), [&] {  // STPQ keeps the inner as it is
    std::vector<uint8_t> q = pack_plane_tile(stpn, nullptr, false);
    q.resize(q.size() - inner.size());
    q.insert(q.end(), mh.begin(), mh.end());
    store_le<uint32_t>(q.data() + kOffByteSize, uint32_t(q.size()));
    return q;
  }());
  auto refused_mh = [&](size_t at, uint8_t value, const char* why) {
    std::vector<uint8_t> b = packed_mh;
    b[at] = value;
    try {
      unpack_plane_tile(b);
      ADD_FAILURE() << "byte " << at << " = " << int(value) << " unpacked";
    } catch (const FormatError& e) {
      EXPECT_NE(std::string(e.what()).find(why), std::string::npos) << e.what();
    }
  };
  const size_t inner_at = want_mh.size() - mh.size();
  refused_mh(kOffFlags, 3, "inner kind");
  refused_mh(inner_at + 6, 5, "a left-out byte not zero");  // levels given anyway
  std::vector<uint8_t> kept = with_mh;  // the whole MH header kept: not the canonical form
  std::copy(packed_mh.begin(), packed_mh.begin() + long(inner_at), kept.begin());
  kept[kOffFlags] = 0;
  EXPECT_THROW(unpack_plane_tile(kept), FormatError);
}

// A hierarchy of one tile of `scene` (bottom-up MH construction of a fresh trace).
struct Traced {
  IntervalTile truth;
  Hierarchy h;
};
Traced trace_tile(const Scene& scene, const LightSpace& light, uint32_t level, uint32_t x, uint32_t y, uint32_t depth) {
  Traced t;
  t.truth = RasterBounds(scene, light).trace(TraceRegion{level, x, y, 1u << depth, 1u << depth});
  t.h = build_hierarchy(t.truth);
  return t;
}

Scene load_model(const char* file) {
  const std::string path = std::string(kModels) + file;
  if (!fs::exists(path)) return {};
  return load_scene(path);
}

// The split answers every finest texel of the trace exactly: planes where they are, the
// pruned hierarchy's encodings elsewhere; and the wrapped buffers open to the same answers.
TEST(PlaneFit, RealOpenMeshTilesAreAnsweredExactlyByPlanesAndTheRest) {
  const Scene scene = load_model("glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb");
  if (scene.triangles.empty()) GTEST_SKIP() << "assimp-testmodels missing: run scripts/deps";
  const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), scene.bounds());
  const uint32_t depth = 7, level = 9;
  uint64_t plane_texels = 0, labelled = 0, table_merged = 0, table_unmerged = 0, values = 0, values_ungrown = 0, values_narrow = 0,
           values_kept = 0;
  uint64_t fewest_checked = 0;
  uint64_t zeros_rounded = 0, zeros_unrounded = 0, z_rounded = 0, z_unrounded = 0, z_stpn = 0, z_packed = 0;
  // Trailing zero bits of a plane tile's table entries (a, b, c), and its table's zlib size.
  auto table_of = [](const std::vector<uint8_t>& tile, uint64_t& zeros, uint64_t& z) {
    const PlaneTileView v = validate_plane_tile(tile);
    for (size_t o = 0; o < v.table.size(); o += 8) zeros += std::countr_zero(load_le<uint64_t>(v.table.data() + o) | (1ull << 63));
    z += zlib_compress(v.table, 6).size();
  };
  for (uint32_t ty = 1; ty < 3; ++ty) {
    const Traced t = trace_tile(scene, light, level, 128 * ty, 192, depth);
    const PlaneSplit s = fit_planes(t.h);
    plane_texels += s.texels;
    {
      // Labelled blocks as a set cover with grown planes answer more of the curved surface's
      // texels than one plane fitted to a block's texels left (grow_labels off).
      PlaneFitOptions ungrown;
      ungrown.grow_labels = false;
      values += s.pruned.valued_count();
      values_ungrown += fit_planes(t.h, ungrown).pruned.valued_count();
      // Wide labelled blocks (up to 8 planes) answer more of them than a palette of 4.
      PlaneFitOptions narrow;
      narrow.max_palette = planes::kPalette;
      values_narrow += fit_planes(t.h, narrow).pruned.valued_count();
      // Coarse values above the blocks that an ancestor's value stands for are dropped.
      PlaneFitOptions kept;
      kept.drop_coarse_values = false;
      values_kept += fit_planes(t.h, kept).pruned.valued_count();
      // The growth's certificate that four texels share no plane only skips refits that fail:
      // every refit tried gives the very same blocks, palettes, labels and planes.
      PlaneFitOptions every_refit;
      every_refit.rule_out = false;
      const PlaneSplit e = fit_planes(t.h, every_refit);
      ASSERT_EQ(e.planes.size(), s.planes.size());
      for (size_t i = 0; i < e.planes.size(); ++i)
        EXPECT_TRUE(std::tie(e.planes[i].start, e.planes[i].shift, e.planes[i].a, e.planes[i].b, e.planes[i].c) ==
                    std::tie(s.planes[i].start, s.planes[i].shift, s.planes[i].a, s.planes[i].b, s.planes[i].c))
            << "plane " << i;
      ASSERT_EQ(e.labelled.size(), s.labelled.size());
      for (size_t i = 0; i < e.labelled.size(); ++i) {
        EXPECT_EQ(e.labelled[i].start, s.labelled[i].start);
        EXPECT_TRUE(std::equal(std::begin(e.labelled[i].label), std::end(e.labelled[i].label), std::begin(s.labelled[i].label)))
            << "labelled block " << i;
        ASSERT_EQ(e.labelled[i].palette.size(), s.labelled[i].palette.size());
        for (size_t k = 0; k < e.labelled[i].palette.size(); ++k)
          EXPECT_TRUE(std::tie(e.labelled[i].palette[k].a, e.labelled[i].palette[k].b, e.labelled[i].palette[k].c) ==
                      std::tie(s.labelled[i].palette[k].a, s.labelled[i].palette[k].b, s.labelled[i].palette[k].c))
              << "labelled block " << i << " palette " << k;
      }
    }
    if (s.planes.empty() && s.labelled.empty()) continue;
    labelled += s.labelled.size();
    EXPECT_LT(s.pruned.valued_count(), t.h.valued_count());
    // A labelled block keeps the fewest of its planes that answer all its texels (the labels
    // chosen after the cover, for the packed form): at least two, each used, none of them
    // answered by the others.
    for (const LabelBlock& lb : s.labelled) {
      const uint32_t x0 = morton_compact(lb.start), y0 = morton_compact(uint64_t(lb.start) >> 1), n = uint32_t(lb.palette.size());
      ASSERT_GE(n, 2u);
      uint32_t used = 0, need[64];
      for (uint32_t i = 0; i < 64; ++i) {
        used |= 1u << lb.label[i];
        const Interval iv = t.truth.at(x0 + i % 8, y0 + i / 8);
        need[i] = 0;
        for (uint32_t e = 0; e < n; ++e) {
          const float v = lb.palette[e].depth(i % 8, i / 8);
          need[i] |= uint32_t(iv.lo <= v && v <= iv.hi) << e;
        }
      }
      EXPECT_EQ(used, (1u << n) - 1) << "every palette plane is used";
      for (uint32_t set = 1; set + 1 < (1u << n); ++set) {
        if (std::popcount(set) >= int(n)) continue;
        bool covers = true;
        for (uint32_t i = 0; i < 64 && covers; ++i) covers = (need[i] & set) != 0;
        EXPECT_FALSE(covers) << "block " << lb.start << ": " << std::popcount(set) << " of its " << n << " planes answer every texel";
      }
      fewest_checked += n;
    }
    {
      // Merging the planes of one surface changes planes, never blocks: the same blocks,
      // fewer table entries (and every texel still exact: checked below on the merged split).
      PlaneFitOptions unmerged;
      unmerged.merge_surfaces = false;
      const PlaneSplit u = fit_planes(t.h, unmerged);
      EXPECT_EQ(u.texels, s.texels);
      ASSERT_EQ(u.planes.size(), s.planes.size());
      for (size_t i = 0; i < u.planes.size(); ++i) EXPECT_EQ(u.planes[i].start, s.planes[i].start);
      ASSERT_EQ(u.labelled.size(), s.labelled.size());
      const std::vector<uint8_t> empty_inner = encode(s.pruned, Encoding::mh);
      table_merged += load_le<uint32_t>(wrap_planes(s.planes, depth, empty_inner, s.labelled).data() + planes::kOffTableCount);
      table_unmerged += load_le<uint32_t>(wrap_planes(u.planes, depth, empty_inner, u.labelled).data() + planes::kOffTableCount);
      // Rounding changes planes, never blocks either: their low bits become zeros.
      PlaneFitOptions unrounded;
      unrounded.round_planes = false;
      const PlaneSplit r = fit_planes(t.h, unrounded);
      EXPECT_EQ(r.texels, s.texels);
      ASSERT_EQ(r.planes.size(), s.planes.size());
      for (size_t i = 0; i < r.planes.size(); ++i) EXPECT_EQ(r.planes[i].start, s.planes[i].start);
      ASSERT_EQ(r.labelled.size(), s.labelled.size());
      table_of(wrap_planes(s.planes, depth, empty_inner, s.labelled), zeros_rounded, z_rounded);
      table_of(wrap_planes(r.planes, depth, empty_inner, r.labelled), zeros_unrounded, z_unrounded);
    }
    for (Encoding e : {Encoding::mh, Encoding::mmh, Encoding::dagmh}) {
      const std::vector<uint8_t> bytes = wrap_planes(s.planes, depth, encode(s.pruned, e), s.labelled);
      {
        // Packed, the same size, back to the very bytes; smaller once deflated.
        const std::vector<uint8_t> packed = pack_plane_tile(bytes);
        ASSERT_EQ(packed.size(), bytes.size());
        std::vector<uint8_t> back = packed;
        unpack_plane_tile(back);
        ASSERT_EQ(back, bytes);
        z_stpn += zlib_compress(bytes, 6).size();
        z_packed += zlib_compress(packed, 6).size();
      }
      const auto ev = open_encoded(e, bytes);
      const uint32_t side = 1u << depth;
      for (uint32_t y = 0; y < side; ++y)
        for (uint32_t x = 0; x < side; ++x) {
          const Interval iv = t.truth.at(x, y);
          const float d = ev->depth(depth, x, y);
          ASSERT_TRUE(iv.lo <= d && d <= iv.hi) << to_string(e) << " texel " << x << "," << y;
        }
      // Coarser levels answer too (the multiresolution map stays complete: within [min lo,
      // max hi] of the texels below); a region shares its value at every texel; PCF is the
      // mean of the single taps.
      std::vector<std::vector<Interval>> hull(depth + 1);
      hull[depth].resize(size_t(side) * side);
      for (uint32_t y = 0; y < side; ++y)
        for (uint32_t x = 0; x < side; ++x) hull[depth][size_t(y) * side + x] = t.truth.at(x, y);
      for (uint32_t l = depth; l-- > 0;) {
        const uint32_t w = 1u << l;
        hull[l].resize(size_t(w) * w);
        for (uint32_t y = 0; y < w; ++y)
          for (uint32_t x = 0; x < w; ++x) {
            Interval& h = hull[l][size_t(y) * w + x];
            h = hull[l + 1][size_t(2 * y) * 2 * w + 2 * x];
            for (uint32_t c = 1; c < 4; ++c) {
              const Interval& ch = hull[l + 1][size_t(2 * y + (c >> 1)) * 2 * w + 2 * x + (c & 1)];
              h.lo = std::min(h.lo, ch.lo), h.hi = std::max(h.hi, ch.hi);
            }
          }
      }
      std::mt19937 rng(ty);
      for (uint32_t l = 0; l <= depth; ++l)
        for (int k = 0; k < 200; ++k) {
          const uint32_t x = rng() % (1u << l), y = rng() % (1u << l);
          const Interval& h = hull[l][(size_t(y) << l) + x];
          ASSERT_TRUE(h.lo <= ev->depth(l, x, y) && ev->depth(l, x, y) <= h.hi) << "level " << l << " " << x << "," << y;
          const DepthRegion reg = ev->depth_region(l, x, y);
          ASSERT_EQ(reg.value, ev->depth(l, x, y));
          const uint32_t rx = (x >> reg.shift << reg.shift) + rng() % (1u << reg.shift);
          const uint32_t ry = (y >> reg.shift << reg.shift) + rng() % (1u << reg.shift);
          ASSERT_EQ(ev->depth(l, rx, ry), reg.value) << "level " << l << " region " << reg.shift;
          const uint32_t r = 1 + 2 * (rng() % 5);
          const float receiver = ev->depth(l, x, y) + (k % 3 == 0 ? 0.0f : 0.001f * float(int(rng() % 21) - 10));
          ASSERT_EQ(ev->pcf(l, x, y, r, receiver), ev->Evaluator::pcf(l, x, y, r, receiver));
        }
    }
  }
  EXPECT_GT(plane_texels, 0u) << "the engine's flat faces seen at a slant are planes";
  EXPECT_GT(labelled, 0u) << "blocks across the engine's edges are labelled";
  EXPECT_GT(fewest_checked, 0u);
  EXPECT_LT(values, values_ungrown) << "grown labels leave fewer values to the inner trees";
  EXPECT_LT(values, values_narrow) << "wide labelled blocks leave fewer values to the inner trees";
  EXPECT_LT(values, values_kept) << "coarse values that an ancestor's value stands for are dropped";
  EXPECT_LT(table_merged, table_unmerged) << "planes of one surface found on separate blocks are merged";
  EXPECT_GT(zeros_rounded, zeros_unrounded + 20 * table_merged) << "rounded planes end in zero bits";
  EXPECT_LT(z_rounded, z_unrounded) << "rounded planes deflate smaller";
  EXPECT_LT(z_packed, z_stpn) << "packed plane tiles deflate smaller";
}

TEST(PlaneFit, ABlockAcrossTwoPlanesIsNoPlane) {
  // Two slopes meeting in the middle of an 8x8 block, one float per texel.
  std::vector<float> lo(64), hi(64);
  for (uint32_t i = 0; i < 64; ++i) {
    const double x = i % 8, y = i / 8;
    lo[i] = hi[i] = float(0.25 + 0.001 * y + (x < 4 ? 0.0003 * x : 0.0012 - 0.0002 * (x - 4)));
  }
  Plane p;
  EXPECT_FALSE(fit_block(lo, hi, 3, p));
  for (uint32_t i = 0; i < 64; ++i) lo[i] = hi[i] = float(0.25 + 0.001 * (i / 8) + 0.0003 * (i % 8));
  ASSERT_TRUE(fit_block(lo, hi, 3, p));
  for (uint32_t i = 0; i < 64; ++i) EXPECT_EQ(p.depth(i % 8, i / 8), lo[i]);
}

// Packs built with plane tiles, every texel against a fresh trace (as RealAssetsLossless
// does for the encodings alone), on three real open-mesh assets.
struct Case {
  const char* file;
  Encoding encoding;
  const char* light;
};

class PlanePacks : public ::testing::TestWithParam<Case> {};

TEST_P(PlanePacks, EveryTexelIsWithinTheFreshTraceAndPlaneTilesAreUsed) {
  const Case& c = GetParam();
  const Scene scene = load_model(c.file);
  if (scene.triangles.empty()) GTEST_SKIP() << c.file << " missing: run scripts/deps (assimp-testmodels)";
  const LightSpace light = LightSpace::fit(LightSpec::parse(c.light), scene.bounds());
  // Level 9 at every scale: at level 8 spider.fbx's blocks are too small for a plane to pay.
  const uint32_t L = 9;
  MapBuildOptions o;
  o.map_level = L;
  o.encoding = c.encoding;
  o.skip_level = 3;
  o.dagmh_dictionary = o.dagmh_mixed_tiles = c.encoding == Encoding::dagmh;
  o.planes = true;
  fs::create_directories(SHADOWTILE_TEST_TMP);
  const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/planes_" + fs::path(c.file).stem().string() + "_" +
                           to_string(c.encoding) + ".pack";
  build_map(scene, light, o, path);
  auto reader = PackReader::open(path);
  EXPECT_TRUE(reader->header().flags & kFeaturePlaneTiles) << "some tile stores planes";
  EXPECT_TRUE(reader->header().flags & kFeaturePackedPlaneTiles) << "plane tiles are stored packed";
  EXPECT_TRUE(reader->header().flags & kFeaturePredictedPlaneLabels) << "their labels predicted (STPL)";
  // Stored packed (STPQ), read back as STPN: never more stored bytes than STPN's.
  uint64_t plane_tiles = 0, packed_tiles = 0, wide_tiles = 0, stored = 0, stpn_stored = 0;
  for (const TileIndexEntry& t : reader->tiles()) {
    if (t.kind != TileKind::encoded) continue;
    const std::vector<uint8_t> raw = reader->read_raw(t.id);
    if (!is_plane_buffer(raw)) continue;
    ++plane_tiles;
    const std::vector<uint8_t> as_stored = zlib_decompress(reader->read_stored(t.id), t.raw_size, "test");
    packed_tiles += is_packed_plane_tile(as_stored);
    wide_tiles += (plane_tile_features(as_stored) & kFeatureWidePlaneBlocks) != 0;  // version 3
    stored += t.stored_size;
    stpn_stored += zlib_compress(raw, 6).size();
  }
  EXPECT_GT(plane_tiles, 0u);
  EXPECT_GT(packed_tiles, 0u);
  EXPECT_LT(stored, stpn_stored);
  // Feature wide_plane_blocks exactly when some plane tile is version 3 (wide labelled blocks).
  EXPECT_EQ(bool(reader->header().flags & kFeatureWidePlaneBlocks), wide_tiles > 0);
  const bool wide = wide_tiles > 0;
  if (std::string(c.file).find("2CylinderEngine") != std::string::npos) {
    EXPECT_TRUE(wide) << "the engine has wide blocks";
  }
  const IntervalTile truth = RasterBounds(scene, light).trace(TraceRegion{L, 0, 0, 1u << L, 1u << L});
  PackEvaluator eval(std::move(reader));
  EXPECT_EQ(fields::first_violation(truth, [&](uint32_t i, uint32_t j) { return eval.depth(L, i, j); }), "");
  // Without the feature bits (header CRC fixed) a packed tile is refused by name.
  std::vector<uint8_t> file;
  {
    std::ifstream f(path, std::ios::binary);
    file.assign(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
  }
  // Each case takes its bits off the file the case before left (the wide bit last).
  for (const auto& [bits, name] : {std::pair{uint32_t(kFeaturePredictedPlaneLabels), "without feature predicted_plane_labels"},
                                   std::pair{uint32_t(kFeaturePredictedPlaneLabels | kFeaturePackedPlaneTiles),
                                             "without feature packed_plane_tiles"},
                                   std::pair{wide ? uint32_t(kFeatureWidePlaneBlocks) : 0u, "without feature wide_plane_blocks"}}) {
    if (bits == 0) continue;  // no version 3 tile
    PackHeader h = PackHeader::parse(std::span<const uint8_t>(file.data(), kPackHeaderBytes), path);
    h.flags &= ~bits;
    const auto head = h.serialize();
    std::memcpy(file.data(), head.data(), head.size());
    {
      std::ofstream f(path, std::ios::binary | std::ios::trunc);
      f.write(reinterpret_cast<const char*>(file.data()), std::streamsize(file.size()));
    }
    try {
      PackReader::open(path)->verify();
      ADD_FAILURE() << "a packed plane tile read " << name;
    } catch (const FormatError& e) {
      EXPECT_NE(std::string(e.what()).find(name), std::string::npos) << e.what();
    }
  }
  fs::remove(path);
}

INSTANTIATE_TEST_SUITE_P(
    Assimp, PlanePacks,
    ::testing::Values(Case{"Collada/teapots.DAE", Encoding::dagmh, "sun:azimuth=30,elevation=50"},
                      Case{"FBX/spider.fbx", Encoding::mmh, "sun:azimuth=120,elevation=70"},
                      Case{"glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb", Encoding::dagmh,
                           "sun:azimuth=200,elevation=35"},
                      Case{"glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb", Encoding::mh,
                           "sun:azimuth=30,elevation=50"}),
    [](const auto& info) { return fs::path(info.param.file).stem().string() + "_" + to_string(info.param.encoding); });

// A real plane tile, cut at every length and with every byte changed: each buffer opens and
// answers every texel inside the tile's bounds (no out-of-range read, no crash) or is refused
// with a FormatError; none takes long or much memory (the tile is a few KiB).
TEST(PlaneTileHostile, TruncatedAndFlippedBuffersAreRefusedOrAnswerSafely) {
  const Scene scene = load_model("glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb");
  if (scene.triangles.empty()) GTEST_SKIP() << "assimp-testmodels missing: run scripts/deps";
  const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), scene.bounds());
  const uint32_t depth = 5;
  std::vector<uint8_t> good;
  for (uint32_t ty = 0; ty < 64 && good.empty(); ++ty) {
    const Traced t = trace_tile(scene, light, 9, 192 + 32 * (ty % 8), 128 + 32 * (ty / 8), depth);
    const PlaneSplit s = fit_planes(t.h, PlaneFitOptions{3, 1, 10});
    auto has = [&](bool wide) {
      return std::any_of(s.labelled.begin(), s.labelled.end(), [&](const LabelBlock& b) { return (b.palette.size() > kPalette) == wide; });
    };
    if (!s.planes.empty() && has(false) && has(true))
      good = wrap_planes(s.planes, depth, encode(s.pruned, Encoding::dagmh), s.labelled);
  }
  ASSERT_FALSE(good.empty()) << "no tile with a plane block, a labelled block and a wide one";
  ASSERT_NO_THROW(open_encoded(Encoding::dagmh, good));
  auto probe = [&](std::span<const uint8_t> b) {
    std::unique_ptr<Evaluator> ev;
    try {
      ev = open_encoded(Encoding::dagmh, b);
    } catch (const FormatError&) {
      return;
    }
    const uint32_t side = 1u << ev->finest_level();
    ASSERT_LE(ev->finest_level(), 16u);
    for (uint32_t y = 0; y < side; y += 3)
      for (uint32_t x = 0; x < side; x += 3) (void)ev->depth(ev->finest_level(), x, y);
  };
  for (size_t n = 0; n < good.size(); ++n) {
    const std::span<const uint8_t> cut(good.data(), n);
    EXPECT_THROW(open_encoded(Encoding::dagmh, cut), FormatError) << "truncated at " << n;
  }
  const size_t header_and_planes = size_t(validate_plane_tile(good).inner.data() - good.data());
  for (size_t i = 0; i < header_and_planes; ++i)
    for (uint8_t flip : {uint8_t(0x01), uint8_t(0x80), uint8_t(0xFF)}) {
      std::vector<uint8_t> bad = good;
      bad[i] ^= flip;
      probe(bad);
    }
  // Its packed form (plane_pack.hpp) likewise: cut or changed, it unpacks or is refused
  // with a FormatError; what unpacks either opens and answers safely or is refused, and
  // what opens packs back to the same bytes (the packed form is canonical).
  const std::vector<uint8_t> packed = pack_plane_tile(good);
  ASSERT_EQ(packed.size(), good.size());
  auto probe_packed = [&](std::vector<uint8_t> b) {
    const std::vector<uint8_t> given = b;
    try {
      unpack_plane_tile(b);
    } catch (const FormatError&) {
      return;
    }
    bool valid = true;
    try {
      validate_plane_tile(b);
    } catch (const FormatError&) {
      valid = false;
    }
    if (valid) {
      ASSERT_EQ(pack_plane_tile(b), given) << "two packed forms of one tile";
    }
    probe(b);
  };
  for (size_t n = 0; n < packed.size(); ++n) {
    std::vector<uint8_t> cut(packed.begin(), packed.begin() + long(n));
    try {
      unpack_plane_tile(cut);
      EXPECT_THROW(validate_plane_tile(cut), FormatError) << "packed, truncated at " << n;
    } catch (const FormatError&) {
    }
  }
  for (size_t i = 0; i < header_and_planes; ++i)
    for (uint8_t flip : {uint8_t(0x01), uint8_t(0x80), uint8_t(0xFF)}) {
      std::vector<uint8_t> bad = packed;
      bad[i] ^= flip;
      probe_packed(std::move(bad));
    }
  std::vector<uint8_t> newer = good;
  newer[kOffVersion] = 4;
  try {
    open_encoded(Encoding::dagmh, newer);
    ADD_FAILURE() << "a version-4 plane tile opened";
  } catch (const FormatError& e) {
    EXPECT_NE(std::string(e.what()).find("version 4, this reader knows 2 and 3"), std::string::npos) << e.what();
  }
  std::vector<uint8_t> nested = wrap_planes({validate_plane_tile(good).plane(0)}, depth, good);
  EXPECT_THROW(open_encoded(Encoding::dagmh, nested), FormatError);
  EXPECT_THROW(open_encoded(Encoding::vsdag, good), FormatError) << "vsdag packs hold no plane tiles";
}

}  // namespace plane_tiles_test
}  // namespace st
