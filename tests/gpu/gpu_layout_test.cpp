// The shared layout header seen from both sides: the C++ static_asserts in gpu/layout.hpp
// pin it to the structures it mirrors; here a shader compiled against it writes back every
// constant it sees, and each must equal the C++ value (a stale or diverging header fails).
#include <gtest/gtest.h>

#include "gpu/layout.hpp"
#include "gpu/layout_probe.hpp"
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
      L::kDictHeaderWords};
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
  EXPECT_EQ(sizeof(dagmh::Header), 72u);
  EXPECT_EQ(offsetof(dagmh::Header, multiplier_offset), 64u);
  EXPECT_EQ(sizeof(dagmh::ChunkInfo), 24u);
  EXPECT_EQ(CutGrid::serialized_size(2), 8u + 4u * 5u + 8u * 16u);  // header, coarse, entries
  EXPECT_EQ(sizeof(GpuQuery), layout::kQueryWords * 4u);
}

}  // namespace
}  // namespace st::gpu
