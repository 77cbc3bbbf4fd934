// The C++ side of the shared layout header (shaders/st_layout.h): the constants, and the
// checks that pin them to the C++ structures they mirror (tile_cache.hpp, tile_cut_grid.hpp,
// the DAG-MH header and chunk infos, GpuQuery). Internal to gpu/.
#pragma once
#include <cstddef>
#include <cstdint>

#include "gpu/gpu_map.hpp"
#include "gpu/shaders/st_layout.h"
#include "tiles/core/dagmh_format.hpp"
#include "tiles/core/encoding.hpp"
#include "tiles/core/vsdag_format.hpp"
#include "tiles/core/mh_octree_format.hpp"
#include "tiles/core/mh_quadtree_format.hpp"
#include "tiles/core/stack_grid.hpp"
#include "tiles/core/stack_slices.hpp"
#include "tiles/core/tile_cache.hpp"
#include "tiles/core/tile_cut_grid.hpp"

namespace st::gpu {

static_assert(layout::kNoSlot == st::kNoSlot);
static_assert(layout::kChildTableWords == (1u << (2 * st::kMaxIndexLevels)));
static_assert(layout::kEntryWords * 4 == st::kGridEntryBytes);
static_assert(layout::kKindConstant == uint32_t(EntryKind::constant) && layout::kKindTile == uint32_t(EntryKind::tile) &&
              layout::kKindIndex == uint32_t(EntryKind::index));
static_assert(layout::kMaxPcf == Evaluator::kMaxPcf);
static_assert(layout::kPcfTableStride == layout::kMaxPcf * layout::kMaxPcf + 1);
static_assert(layout::kMaxMapLevel == mhq::kMaxLevels - 1);
static_assert(layout::kGridHeaderWords * 4 == 8);  // magic + levels before a CutGrid's coarse values
static_assert(uint32_t(Encoding::mh) == 0 && uint32_t(Encoding::mmh) == 1 && uint32_t(Encoding::dagmh) == 2 &&
              uint32_t(Encoding::vsdag) == 3);
// st_vsdag_lit / st_vsdag_depth (st_eval.glsl) read these header words and constants.
static_assert(offsetof(vsdag::Header, xy_bits) == 3 * 4 && offsetof(vsdag::Header, z_bits) == 4 * 4 &&
              offsetof(vsdag::Header, grid_xy_bits) == 5 * 4 && offsetof(vsdag::Header, grid_z_bits) == 6 * 4 &&
              offsetof(vsdag::Header, leaf_offset) == 10 * 4 && offsetof(vsdag::Header, grid_offset) == 11 * 4 &&
              offsetof(vsdag::Header, node_offset) == 12 * 4);
static_assert(vsdag::kLeafXyBits == 3 && vsdag::kZNodeBits == 3 && vsdag::kStateShift == 30 &&
              vsdag::kShadow == 0 && vsdag::kLit == 1 && vsdag::kMixed == 2 && vsdag::kMaxZBits <= 20);
static_assert(layout::kLevelFromFootprint == kLevelFromFootprint);
static_assert(layout::kPcWords * 4 <= 128, "push constants: Vulkan guarantees 128 bytes");
static_assert(layout::kFbRecordWords == 6 && layout::kFbHeaderWords >= 5);
static_assert(layout::kPtHeaderWords > layout::kPtPcfTable && layout::kPtHeaderWords > layout::kPtStack);
static_assert(layout::kPtHeaderWords > layout::kPtDictionary && layout::kPtDictionary > layout::kPtPreview);
static_assert(layout::kPtHeaderWords > layout::kPtDeep && layout::kPtDeep > layout::kPtLight);
// The dictionary block is the DGMD buffer word for word (dagmh_format.hpp DictHeader).
static_assert(offsetof(dagmh::DictHeader, node_words) == layout::kDictNodeWords * 4 &&
              offsetof(dagmh::DictHeader, treelet_count) == layout::kDictTreeletCount * 4 &&
              sizeof(dagmh::DictHeader) == layout::kDictHeaderWords * 4);
static_assert(offsetof(dagmh::Header, version) == 1 * 4 && dagmh::kFlagDictionary == 1);
// What st_eval.glsl reads of the tile formats, by word: the header's word 2 holds
// finest_level, skip_level and flags in bytes 0..2; the sections follow from the counts
// (dagmh::sections_of).
static_assert(dagmh::kTreeletWords == 3 && sizeof(dagmh::ChunkInfo) == 5 * 4 && sizeof(dagmh::Cursor) == 4 * 4 &&
              sizeof(dagmh::Header) == 8 * 4 && dagmh::kChunkValues == 32);
static_assert(offsetof(dagmh::Header, finest_level) == 2 * 4 && offsetof(dagmh::Header, skip_level) == 2 * 4 + 1 &&
              offsetof(dagmh::Header, flags) == 2 * 4 + 2 && offsetof(dagmh::Header, root_ref) == 3 * 4 &&
              offsetof(dagmh::Header, node_words) == 4 * 4 && offsetof(dagmh::Header, treelet_count) == 5 * 4 &&
              offsetof(dagmh::Header, value_count) == 6 * 4);
static_assert(offsetof(dagmh::ChunkInfo, base) == 0 && offsetof(dagmh::ChunkInfo, mask) == 4 &&
              offsetof(dagmh::ChunkInfo, c_l) == 8 && offsetof(dagmh::ChunkInfo, c_f) == 12 &&
              offsetof(dagmh::ChunkInfo, packed) == 16 && dagmh::kBitOffsetBits == 27 && dagmh::kRawFactorCode == 31);
static_assert(dagmh::kRefInner == 0x40000000u && dagmh::kRefTreelet == 0x80000000u && dagmh::kNodeValuedBit == 0x100u &&
              dagmh::kNodeTreeletShift == 4 && dagmh::kTreeletStride[0] == 21 && dagmh::kTreeletStride[1] == 5);
static_assert(mhq::kOffLevels == 6 && mhq::kOffFlags == 7 && mhq::kOffShifts == 16 && mhq::kFlagRootLeaf == 1 &&
              mhq::kCodeLeaf == 1 && mhq::kCodeEmpty == 2 && mhq::kCodeInner == 3);
static_assert(mhq::tree_offset(1) == 16 + 4 && mhq::tree_offset(21) == 16 + 24);
// What st_stack.glsl reads of the MH octree (MHOCT.md): word 1 = version | n << 16 | k << 24,
// word 2 = slices | flags << 16, the shifts from byte 20, the tree at 20 + round_up(L + 1, 4).
static_assert(moct::kOffVersion == 4 && moct::kOffXyLevel == 6 && moct::kOffWLevel == 7 && moct::kOffSlices == 8 &&
              moct::kOffFlags == 10 && moct::kOffShifts == 20 && moct::kFlagRootLeaf == 1);
static_assert(moct::kCodeLeaf == 1 && moct::kCodeEmpty == 2 && moct::kCodeInner == 3 && moct::kMaxLevels == 21);
static_assert(moct::tree_offset(1) == 20 + 4 && moct::tree_offset(21) == 20 + 24);
// What st_stack.glsl reads of a per-slice cell (stack_slices.hpp): the magic, then entry w at
// byte 16 + 8 w; and the MMH magic st_eval.glsl tells a mixed tile by.
static_assert(layout::kSlMagic == kSliceTilesMagic && layout::kSlHeaderWords * 4 == kSliceTilesHeaderBytes &&
              layout::kSlEntryWords * 4 == kSliceTilesEntryBytes && layout::kMmhMagic == mhq::kMagicMmh);
// st_oct_step's far offsets (version 3): off < -32736 reads the far word at pos + 1 + off + 32768.
static_assert(moct::kVersion == 3 && moct::kFarOffsetMin == -32768 && moct::kFarLimit == -32736);
static_assert(layout::kMaxStackCells == kStackMaxCells);
// A split stack entry's kind word: kind | first child << kStFirstChildShift, every cell fits.
static_assert(layout::kStKindSplit == kStackSplit && (uint64_t(layout::kMaxStackCells - 1) << layout::kStFirstChildShift) <= 0xFFFFFFFFu);
static_assert(layout::kStLightWords >= 13 && layout::kStHeaderWords > layout::kStLights);
static_assert(layout::kStLightCentreU == 13 && layout::kStLightCentreV == 14 &&
              layout::kStLightProjection == 15 && layout::kStLightProjection < layout::kStLightWords);
static_assert(layout::kStLightSlopeCap == 16 && layout::kStLightSlopeCap < layout::kStLightWords &&
              (layout::kFlagReceiverPlane & (layout::kFlagSoft | layout::kFlagNeighbourFootprint |
                                             layout::kFlagResumeWalks)) == 0);
static_assert((layout::kFlagSoft & layout::kFlagNeighbourFootprint) == 0 &&
              (layout::kFlagResumeWalks & (layout::kFlagSoft | layout::kFlagNeighbourFootprint)) == 0);
// A stack query is GpuStackQuery word for word; the stack pass's push constants sit where
// the 2D pass keeps its light (which a stack keeps per slice in the stack block).
static_assert(sizeof(GpuStackQuery) == layout::kSqWords * 4 && offsetof(GpuStackQuery, x) == layout::kSqX * 4 &&
              offsetof(GpuStackQuery, y) == layout::kSqY * 4 && offsetof(GpuStackQuery, slice) == layout::kSqSlice * 4 &&
              offsetof(GpuStackQuery, level) == layout::kSqLevel * 4 &&
              offsetof(GpuStackQuery, receiver) == layout::kSqReceiver * 4 &&
              offsetof(GpuStackQuery, footprint) == layout::kSqFootprint * 4 && offsetof(GpuStackQuery, r) == layout::kSqR * 4);
static_assert(layout::kPcSliceA >= layout::kPcOrigin && layout::kPcTimeWeight < layout::kPcNear &&
              layout::kPcTimeWeight < layout::kPcWords);
static_assert((layout::kFbStackKeyBit & layout::kFbChildKeyBit) == 0 && layout::kMaxStackCells <= layout::kFbStackKeyBit);
// A deep key's grid index has 2 (D - b) <= 20 bits (deep::kMaxTilesPerSideBits): below the bit.
static_assert(((layout::kFbChildKeyBit | layout::kFbStackKeyBit) & layout::kFbDeepKeyBit) == 0 &&
              (uint64_t(1) << 20) <= layout::kFbDeepKeyBit);
static_assert(layout::kDpPresence < layout::kDpHeaderWords && layout::kDpPresence != layout::kDpDepthBias);

}  // namespace st::gpu
