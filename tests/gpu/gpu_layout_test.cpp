// The shared layout header seen from both sides: the C++ static_asserts in gpu/layout.hpp
// pin it to the structures it mirrors; here a shader compiled against it writes back every
// constant it sees, and each must equal the C++ value (a stale or diverging header fails).
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <random>

#include "gpu/layout.hpp"
#include "tests/gpu/layout_probe.hpp"
#include "tiles/core/deep_format.hpp"
#include "tests/gpu/gpu_test_util.hpp"

namespace st::gpu {
namespace {

TEST(GpuLayout, TheShaderSeesEveryConstantTheCppSideSees) {
  namespace L = layout;
  const std::vector<uint32_t> want = {
      L::kLayoutVersion, L::kPageMagic, L::kPtMagic, L::kPtVersion, L::kPtMapLevel, L::kPtSkipLevel,
      L::kPtEncoding, L::kPtSlotCount, L::kPtSlotWords, L::kPtSkipCoarse, L::kPtSkipEntries, L::kPtSkipSlots,
      L::kPtChildSlots, L::kPtPcfTable, L::kPtPreview, L::kPvLevels, L::kPvMaskWords, L::kPvCells,
      L::kPvValues, L::kPvHeaderWords, L::kPvCellHeaderWords, L::kPtHeaderWords, L::kNoSlot, L::kChildTableWords, L::kEntryWords,
      L::kKindConstant, L::kKindTile, L::kKindIndex, L::kMaxPcf, L::kPcfTableStride, L::kMaxMapLevel,
      L::kLitDepthBits, L::kGridHeaderWords, L::kQueryWords, L::kQueryX, L::kQueryY, L::kQueryReceiver,
      L::kQueryFootprint, L::kQueryR, L::kQueryLevel, L::kLevelFromFootprint, L::kFbUsed, L::kFbDropped,
      L::kFbHoles, L::kFbAbsentTaps, L::kFbCapacity, L::kFbHeaderWords, L::kFbRecordWords, L::kFbRecCount,
      L::kFbRecLevel, L::kFbRecX, L::kFbRecY, L::kFbRecValue, L::kFbRecKind, L::kFbMaxProbes, L::kFbChildKeyBit,
      L::kPcCount, L::kPcHeight, L::kPcKernel, L::kPcFlags, L::kPcOrigin, L::kPcAxisU, L::kPcAxisV, L::kPcForward,
      L::kPcNear, L::kPcNormalOffset, L::kPcFootprint, L::kPcWords, L::kFlagNeighbourFootprint,
      L::kWorkgroupSize, L::kProbeWords, L::kPtDictionary, L::kDictNodeWords, L::kDictTreeletCount,
      L::kDictHeaderWords,
      L::kPtStack, L::kStXyLevel, L::kStWLevel, L::kStSlices, L::kStSkipLevel, L::kStEntries, L::kStCellSlots,
      L::kStLights, L::kStHeaderWords, L::kStLightWords, L::kMaxStackCells, L::kSqWords, L::kSqX, L::kSqY,
      L::kSqSlice, L::kSqLevel, L::kSqReceiver, L::kSqFootprint, L::kSqR, L::kFbStackKeyBit, L::kPcSliceA,
      L::kPcSliceB, L::kPcTimeWeight, L::kStLightCentreU, L::kStLightCentreV, L::kStLightProjection, L::kFlagSoft,
      L::kFlagResumeWalks, L::kPtDeep, L::kDpLevel, L::kDpSideBits, L::kDpCount, L::kDpCapacity,
      L::kDpDepthBias, L::kDpHeaderWords, L::kDeepQuery, L::kDtTexelCount, L::kDtHeaderWords, L::kStLightSlopeCap,
      L::kFlagReceiverPlane, L::kStKindSplit, L::kStFirstChildShift};
  ASSERT_LE(want.size(), L::kProbeWords);
  uint64_t messages = 0;
  const std::vector<uint32_t> got = run_layout_probe(gputest::device(), true, &messages);
  ASSERT_EQ(got.size(), L::kProbeWords);
  for (size_t i = 0; i < want.size(); ++i) EXPECT_EQ(got[i], want[i]) << "constant #" << i;
  for (size_t i = want.size(); i < got.size(); ++i) EXPECT_EQ(got[i], 0u) << "word " << i;
  EXPECT_EQ(messages, 0u);
}

// The page-table offsets and the tile structures the shader reads by word.
TEST(GpuLayout, CppStructuresMatchTheWordOffsetsTheShaderUses) {
  EXPECT_EQ(sizeof(dagmh::Header), 32u);
  EXPECT_EQ(offsetof(dagmh::Header, value_count), 24u);
  EXPECT_EQ(sizeof(dagmh::ChunkInfo), 20u);
  EXPECT_EQ(CutGrid::serialized_size(2), 8u + 4u * 5u + 8u * 16u);  // header, coarse, entries
  EXPECT_EQ(sizeof(GpuQuery), layout::kQueryWords * 4u);
  EXPECT_EQ(sizeof(GpuStackQuery), layout::kSqWords * 4u);
  EXPECT_EQ(moct::tree_offset(moct::Geometry{6, 4}.levels()), 28u);  // 20 + round_up(7, 4): st_oct_depth's tree word 7
}

// The stack block of a GpuMap's page table, as GPU_LAYOUT.md draws it: header word
// offsets, then the K coarse-level offsets (the header's 8 words, then K words).
TEST(GpuLayout, StackBlockHeaderWordsAreWhereTheDrawingPutsThem) {
  namespace L = layout;
  EXPECT_EQ(L::kPtStack, 14u);
  EXPECT_EQ(L::kStXyLevel, 0u);
  EXPECT_EQ(L::kStWLevel, 1u);
  EXPECT_EQ(L::kStSlices, 2u);
  EXPECT_EQ(L::kStSkipLevel, 3u);
  EXPECT_EQ(L::kStEntries, 4u);
  EXPECT_EQ(L::kStCellSlots, 5u);
  EXPECT_EQ(L::kStLights, 6u);
  EXPECT_EQ(L::kStHeaderWords, 8u);
  EXPECT_EQ(L::kStLightWords, 17u);
  EXPECT_EQ(L::kSqWords, 7u);
  EXPECT_EQ(L::kFbStackKeyBit, 0x40000000u);
  EXPECT_EQ(L::kPcSliceA, 4u);
  EXPECT_EQ(L::kPcSliceB, 5u);
  EXPECT_EQ(L::kPcTimeWeight, 6u);
  EXPECT_EQ(L::kStLightCentreU, 13u);
  EXPECT_EQ(L::kStLightCentreV, 14u);
  EXPECT_EQ(L::kStLightProjection, 15u);
  EXPECT_EQ(L::kStLightSlopeCap, 16u);
  EXPECT_EQ(L::kFlagReceiverPlane, 8u);
  EXPECT_EQ(L::kFlagSoft, 2u);
  EXPECT_EQ(L::kFlagResumeWalks, 4u);
  EXPECT_EQ(L::kStKindSplit, 2u);  // layout version 8: split cells, kind | first child << 8
  EXPECT_EQ(L::kStFirstChildShift, 8u);
}

// The page-table header and the deep block as GPU_LAYOUT.md draws them ("The page table",
// "The deep block"): layout version 6 added the header word kPtDeep (7: a light's word
// kStLightSlopeCap; 8: split stack entries; 9: the DAG-MH dictionary in the pool).
TEST(GpuLayout, DeepBlockWordsAreWhereTheDrawingPutsThem) {
  namespace L = layout;
  EXPECT_EQ(L::kLayoutVersion, 9u);
  EXPECT_EQ(L::kPtLight, 15u);
  EXPECT_EQ(L::kPtDeep, 16u);
  EXPECT_EQ(L::kPtHeaderWords, 17u);
  EXPECT_EQ(L::kDpLevel, 0u);
  EXPECT_EQ(L::kDpSideBits, 1u);
  EXPECT_EQ(L::kDpCount, 2u);
  EXPECT_EQ(L::kDpCapacity, 3u);
  EXPECT_EQ(L::kDpDepthBias, 4u);
  EXPECT_EQ(L::kDpPresence, 5u);
  EXPECT_EQ(L::kFbDeepKeyBit, 0x20000000u);
  EXPECT_EQ(L::kDpHeaderWords, 8u);
  EXPECT_EQ(L::kDeepQuery, 0xFFFFFFFEu);
  EXPECT_EQ(L::kDtTexelCount, 5u);
  EXPECT_EQ(L::kDtHeaderWords, 12u);
  EXPECT_EQ(deep::kDepthFlushBelow, std::ldexp(1.0f, -103));
  EXPECT_EQ(sizeof(GpuDeepQuery), 16u);
}

// st_fdiv (shaders/st_fdiv.glsl), the division of the stack passes' perspective divide
// and soft average, on the device: every quotient has the bits of the CPU's float
// division (IEEE 754, round to nearest even; a NaN quotient only needs to be a NaN), over
// random bit patterns (every exponent: subnormals, infinities, NaNs), near-equal
// significands, subnormal quotients, exact quotients and halfway cases, the passes' own
// operands (PCF sums over slice counts, light-space coordinates over depths) and the
// special values against each other. Each pair runs twice: as the passes divide (skew 0)
// and with the device's estimate moved by -3..3 ulps (st_fdiv_est), past Vulkan's 2.5-ulp
// division, so the exact steps are checked on a device that divides exactly (lavapipe).
TEST(GpuLayout, StFdivRoundsLikeTheCpusFloatDivision) {
  std::vector<uint32_t> a, b;
  auto add = [&](float x, float y) { a.push_back(std::bit_cast<uint32_t>(x)), b.push_back(std::bit_cast<uint32_t>(y)); };
  std::mt19937 rng(7);
  for (int i = 0; i < 60000; ++i) a.push_back(rng()), b.push_back(rng());
  for (int i = 0; i < 20000; ++i) {
    const uint32_t x = rng();
    a.push_back(x), b.push_back((x & 0xFF800000u) | (rng() & 0x7FFFFFu));  // quotients near 1
    a.push_back(rng() & 0x80FFFFFFu), b.push_back(0x5E000000u | (rng() & 0x807FFFFFu));  // subnormal quotients
  }
  for (uint32_t n = 1; n <= 256; ++n)
    for (uint32_t lit = 0; lit <= 81; lit += 3) add(float(lit) / 81.0f * float(n) / 3.0f, float(n));
  std::uniform_real_distribution<float> coord(-2.0f, 2.0f), depth(-0.1f, 1.5f);
  for (int i = 0; i < 20000; ++i) add(coord(rng), depth(rng));
  const uint32_t special[] = {0u, 0x80000000u, 0x7F800000u, 0xFF800000u, 0x7FC00000u, 1u, 0x807FFFFFu,
                              0x00800000u, 0x7F7FFFFFu, 0x3F800000u, 0xBF800000u, 0x00400000u, 0x34000000u};
  for (uint32_t x : special)
    for (uint32_t y : special) a.push_back(x), b.push_back(y);
  for (int i = 0; i < 20000; ++i) {  // exact quotients: b * q with a short q
    const float y = std::bit_cast<float>(0x3F800000u | (uint32_t(rng()) & 0x7FFFFFu));
    add(y * std::bit_cast<float>(0x3F800000u | (uint32_t(rng()) & 0xFFFu) << 11), y);
  }
  for (uint32_t m = 1; m < 64; ++m)  // halfway quotients (only subnormal ones exist): ties to even
    for (uint32_t k = 1; k <= 4; ++k) a.push_back(m), b.push_back((127u + k) << 23);
  for (int i = 0; i < 5000; ++i) {  // significands at the ends of [1, 2): quotients just under 1 and 2, and near min/max
    const uint32_t lo = uint32_t(rng()) & 0x3Fu, hi = 0x7FFFFFu - (uint32_t(rng()) & 0x3Fu);
    const uint32_t e = (uint32_t(rng()) % 254u + 1u) << 23, r = uint32_t(rng()) & 0x7FFFFFu;
    a.push_back(e | lo), b.push_back(0x3F800000u | hi);
    a.push_back(e | hi), b.push_back(0x3F800000u | lo);
    a.push_back(0x7F000000u | hi), b.push_back(0x00800000u | r);  // overflow to inf
    a.push_back(0x00800000u | lo), b.push_back(0x4B000000u | r);  // subnormal quotients, rounding across
  }
  const size_t pairs = a.size();
  std::vector<int32_t> skew(pairs, 0);
  a.reserve(2 * pairs), b.reserve(2 * pairs), skew.reserve(2 * pairs);
  for (size_t i = 0; i < pairs; ++i) a.push_back(a[i]), b.push_back(b[i]), skew.push_back(int32_t(i % 7) - 3);
  uint64_t messages = 0;
  const std::vector<uint32_t> got = run_fdiv_probe(gputest::device(), true, a, b, skew, &messages);
  ASSERT_EQ(got.size(), a.size());
  size_t bad = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    const float want = std::bit_cast<float>(a[i]) / std::bit_cast<float>(b[i]);
    const bool same = std::isnan(want) ? std::isnan(std::bit_cast<float>(got[i])) : std::bit_cast<uint32_t>(want) == got[i];
    if (!same && bad++ < 5)
      ADD_FAILURE() << std::hex << a[i] << " / " << b[i] << std::dec << " (skew " << skew[i] << std::hex << "): gpu "
                    << got[i] << ", cpu " << std::bit_cast<uint32_t>(want);
  }
  EXPECT_EQ(bad, 0u);
  EXPECT_EQ(messages, 0u);
}

}  // namespace
}  // namespace st::gpu
