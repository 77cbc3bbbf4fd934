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
#include "tiles/core/mh_quadtree_format.hpp"
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
static_assert(layout::kPtHeaderWords > layout::kPtDictionary && layout::kPtDictionary > layout::kPtPreview);
// The dictionary block is the DGMD buffer word for word (dagmh_format.hpp DictHeader).
static_assert(offsetof(dagmh::DictHeader, node_words) == layout::kDictNodeWords * 4 &&
              offsetof(dagmh::DictHeader, treelet_count) == layout::kDictTreeletCount * 4 &&
              sizeof(dagmh::DictHeader) == layout::kDictHeaderWords * 4);
static_assert(offsetof(dagmh::Header, version) == 1 * 4 && dagmh::kVersionDictionary == 2);
// What st_eval.glsl reads of the tile formats, by word:
static_assert(dagmh::kTreeletWords == 3 && sizeof(dagmh::ChunkInfo) == 6 * 4 && sizeof(dagmh::Cursor) == 4 * 4);
static_assert(offsetof(dagmh::Header, finest_level) == 3 * 4 && offsetof(dagmh::Header, skip_level) == 4 * 4 &&
              offsetof(dagmh::Header, root_ref) == 5 * 4 && offsetof(dagmh::Header, skip_offset) == 12 * 4 &&
              offsetof(dagmh::Header, node_offset) == 13 * 4 && offsetof(dagmh::Header, treelet_offset) == 14 * 4 &&
              offsetof(dagmh::Header, chunk_offset) == 15 * 4 && offsetof(dagmh::Header, multiplier_offset) == 16 * 4);
static_assert(offsetof(dagmh::ChunkInfo, base) == 0 && offsetof(dagmh::ChunkInfo, mask) == 4 &&
              offsetof(dagmh::ChunkInfo, c_l) == 8 && offsetof(dagmh::ChunkInfo, c_f) == 12 &&
              offsetof(dagmh::ChunkInfo, bit_offset) == 16 && offsetof(dagmh::ChunkInfo, factor_bits) == 20);
static_assert(dagmh::kRefInner == 0x40000000u && dagmh::kRefTreelet == 0x80000000u && dagmh::kNodeValuedBit == 0x100u &&
              dagmh::kNodeTreeletShift == 4 && dagmh::kTreeletStride[0] == 21 && dagmh::kTreeletStride[1] == 5);
static_assert(mhq::kOffLevels == 6 && mhq::kOffFlags == 7 && mhq::kOffShifts == 16 && mhq::kFlagRootLeaf == 1 &&
              mhq::kCodeLeaf == 1 && mhq::kCodeEmpty == 2 && mhq::kCodeInner == 3);
static_assert(mhq::tree_offset(1) == 16 + 4 && mhq::tree_offset(21) == 16 + 24);

}  // namespace st::gpu
