#version 450
// Writes the layout constants this shader compiles against, in a fixed order, so a test
// compares them with the C++ side's (tests/gpu/gpu_layout_test.cpp).
// With a count in push-constant word kPcCount it probes st_fdiv instead: invocation i
// writes st_fdiv_est(a, b, skew) of input words 3i, 3i + 1 and 3i + 2 (a, b as floats, skew
// as an int: the device's estimate moved by that many ulps; 0 is st_fdiv) to output word i
// (the division test).
#include "st_buffers.glsl"

#include "st_stack.glsl"

void main() {
  const uint count = st_pc.w[kPcCount];
  if (count != 0u) {
    const uint i = gl_GlobalInvocationID.x;
    if (i < count)
      st_output[i] = st_fdiv_est(uintBitsToFloat(st_input_words[3u * i]), uintBitsToFloat(st_input_words[3u * i + 1u]),
                                 int(st_input_words[3u * i + 2u]));
    return;
  }
  if (gl_GlobalInvocationID.x != 0u) return;
  const uint v[] = uint[](kLayoutVersion, kPageMagic, kPtMagic, kPtVersion, kPtMapLevel, kPtSkipLevel,
                          kPtEncoding, kPtSlotCount, kPtSlotWords, kPtSkipCoarse, kPtSkipEntries, kPtSkipSlots,
                          kPtChildSlots, kPtPcfTable, kPtPreview, kPvLevels, kPvMaskWords, kPvCells, kPvValues,
                          kPvHeaderWords, kPvCellHeaderWords, kPtHeaderWords, kNoSlot, kChildTableWords, kEntryWords,
                          kKindConstant, kKindTile, kKindIndex, kMaxPcf, kPcfTableStride, kMaxMapLevel,
                          kLitDepthBits, kGridHeaderWords, kQueryWords, kQueryX, kQueryY, kQueryReceiver,
                          kQueryFootprint, kQueryR, kQueryLevel, kLevelFromFootprint, kFbUsed, kFbDropped,
                          kFbHoles, kFbAbsentTaps, kFbCapacity, kFbHeaderWords, kFbRecordWords, kFbRecCount,
                          kFbRecLevel, kFbRecX, kFbRecY, kFbRecValue, kFbRecKind, kFbMaxProbes, kFbChildKeyBit,
                          kPcCount, kPcHeight, kPcKernel, kPcFlags, kPcOrigin, kPcAxisU, kPcAxisV, kPcForward,
                          kPcNear, kPcNormalOffset, kPcFootprint, kPcWords, kFlagNeighbourFootprint,
                          kWorkgroupSize, kProbeWords, kPtDictionary, kDictNodeWords, kDictTreeletCount,
                          kDictHeaderWords,
                          kPtStack, kStXyLevel, kStWLevel, kStSlices, kStSkipLevel, kStEntries, kStCellSlots,
                          kStLights, kStHeaderWords, kStLightWords, kMaxStackCells, kSqWords, kSqX, kSqY, kSqSlice,
                          kSqLevel, kSqReceiver, kSqFootprint, kSqR, kFbStackKeyBit, kPcSliceA, kPcSliceB,
                          kPcTimeWeight, kStLightCentreU, kStLightCentreV, kStLightProjection, kFlagSoft,
                          kFlagResumeWalks, kPtDeep, kDpLevel, kDpSideBits, kDpCount, kDpCapacity, kDpDepthBias, kDpHeaderWords, kDeepQuery, kDtTexelCount, kDtHeaderWords,
                          kStLightSlopeCap, kFlagReceiverPlane, kStKindSplit, kStFirstChildShift);
  for (uint i = 0u; i < kProbeWords; ++i) st_output[i] = uintBitsToFloat(i < v.length() ? v[i] : 0u);
}
