// The buffer layouts the GPU evaluators read, shared by GLSL and C++ (the way PNanoVDB.h
// mirrors NanoVDB.h): C++ includes it for the constants and the GLSL shaders include it
// for the same names. Drawn with sizes and offsets in gpu/GPU_LAYOUT.md; every constant
// here is a FORMAT CONSTANT of the GPU mirror (tests/gpu/gpu_layout_test.cpp pins it, on
// the C++ side with static_asserts and on the shader side with a probe shader that
// writes back every constant it sees).
//
// All buffers are arrays of 32-bit words. Offsets are in words unless a name says bytes.
#ifndef SHADOWTILE_GPU_ST_LAYOUT_H
#define SHADOWTILE_GPU_ST_LAYOUT_H

#ifdef __cplusplus
#include <cstdint>
#define ST_UINT(name, value) inline constexpr uint32_t name = value;
namespace st::gpu::layout {
#else
#define ST_UINT(name, value) const uint name = value;
#endif

ST_UINT(kLayoutVersion, 9u)  // 2: the map preview (kPtPreview); 3: the stack block (kPtStack); 4: the DAG-MH dictionary (kPtDictionary); 5: the 2D light (kPtLight); 6: the deep block (kPtDeep); 7: a light's receiver-slope cap (kStLightSlopeCap); 8: split stack cells (kStKindSplit); 9: the DAG-MH dictionary in the pool

// ---- page-table buffer (binding kBindPage) ----
// header words, then the skip grid's coarse values and entries, the skip grid's slot
// pointers, one child-pointer table per slot, and the PCF quotient table.
ST_UINT(kPageMagic, 0x50475453u)  // "STGP"
ST_UINT(kPtMagic, 0u)
ST_UINT(kPtVersion, 1u)
ST_UINT(kPtMapLevel, 2u)       // L: finest level of the map
ST_UINT(kPtSkipLevel, 3u)      // K: level of the skip grid's entries
ST_UINT(kPtEncoding, 4u)       // 0 MH, 1 MMH, 2 DAG-MH, 3 vsdag (st::Encoding)
ST_UINT(kPtSlotCount, 5u)
ST_UINT(kPtSlotWords, 6u)      // slot stride in the pool, in words
ST_UINT(kPtSkipCoarse, 7u)     // word offset: (4^K - 1) / 3 coarse values (f32)
ST_UINT(kPtSkipEntries, 8u)    // word offset: 4^K entries, 2 words each (f32 value, kind | levels << 8)
ST_UINT(kPtSkipSlots, 9u)      // word offset: 4^K slot pointers (kNoSlot: not on the GPU)
ST_UINT(kPtChildSlots, 10u)    // word offset: slot_count * kChildTableWords slot pointers
ST_UINT(kPtPcfTable, 11u)      // word offset: kMaxPcf * kPcfTableStride f32 quotients
ST_UINT(kPtPreview, 12u)       // word offset: the map preview (kPv* header, then its arrays)
ST_UINT(kPtDictionary, 13u)    // POOL word offset: the pack's DAG-MH dictionary (kDict*), 0: none
ST_UINT(kPtStack, 14u)         // word offset: the stack block (kSt*) of a stack map; 0 for a 2D map
ST_UINT(kPtLight, 15u)         // word offset: a 2D map's light space (kStLightWords words, the stack block's
                               // light layout; projection 0), 0: none (a stack map, or a light the pass refuses)
ST_UINT(kPtDeep, 16u)          // word offset: the deep block (kDp*) of a 2D map with a deep part; 0: none
ST_UINT(kPtHeaderWords, 17u)

// The DAG-MH dictionary block (tiles/core/DAGMH.md "Dictionary"), in the slot pool after the
// last slot, at the pool word the page table's kPtDictionary names: the dictionary buffer
// MapInfo carries (inflated), word for word: its 8-word header (D node
// words at kDictNodeWords, T treelets at kDictTreeletCount), D node words, 3 T treelet
// words. A version-2 tile's inner reference i < D is the dictionary's node word i, else
// its own word i - D; a treelet t < T the dictionary's, else its own t - T.
ST_UINT(kDictNodeWords, 3u)
ST_UINT(kDictTreeletCount, 4u)
ST_UINT(kDictHeaderWords, 8u)

// The map preview block (tiles/core/map_preview.hpp), at word kPtPreview: a header, then
// one ordinal per skip-grid entry (kNoSlot: constant), per cell kPvCellHeaderWords words
// (first value's index, the entry's value) and 2 * mask_words mask words (each u64 mask
// word as its low then high half), then the stored values (f32).
ST_UINT(kPvLevels, 0u)          // p: preview levels below K (0: none)
ST_UINT(kPvMaskWords, 1u)       // u64 mask words per cell
ST_UINT(kPvCells, 2u)           // word offset of the cell records
ST_UINT(kPvValues, 3u)          // word offset of the values
ST_UINT(kPvHeaderWords, 4u)     // the ordinals follow
ST_UINT(kPvCellHeaderWords, 2u)

ST_UINT(kNoSlot, 0xFFFFFFFFu)
ST_UINT(kChildTableWords, 256u)  // 4^kMaxIndexLevels entries of an index tile
ST_UINT(kEntryWords, 2u)
ST_UINT(kKindConstant, 0u)       // st::EntryKind
ST_UINT(kKindTile, 1u)
ST_UINT(kKindIndex, 2u)
ST_UINT(kMaxPcf, 9u)
ST_UINT(kPcfTableStride, 82u)    // lit taps 0..81; entry (r - 1) * stride + lit = float(lit) / float(r * r)
ST_UINT(kMaxMapLevel, 20u)
ST_UINT(kLitDepthBits, 0x3F800000u)  // 1.0f

// An index tile in a slot is a serialized CutGrid: magic, levels, coarse values, entries.
ST_UINT(kGridHeaderWords, 2u)

// The stack block (a map of a stack pack: tiles/PACK.md "Stack packs", tiles/core/MHOCT.md),
// at word kPtStack: a header, then K words (the word offset of octree level l's coarse
// values, l < K), then the coarse values (f32; level l holds 4^a(l) 2^b(l) values in
// (w, y, x) row-major order), the cells' entries (kEntryWords each: f32 value, kind 0
// constant / 1 tile / kStKindSplit | first child << kStFirstChildShift; level K's cells,
// then a version-2 grid's split children, tiles/core/stack_grid.hpp), one slot pointer per
// cell (kNoSlot: not on the GPU), and one
// float32 light space per slice (kStLightWords each: the order of kPcOrigin..kPcNear, then
// a perspective light's centre and the projection word; GPU_LAYOUT.md "The stack block").
ST_UINT(kStXyLevel, 0u)         // n: slices are 2^n texels a side
ST_UINT(kStWLevel, 1u)          // k: 2^(k-1) < N <= 2^k
ST_UINT(kStSlices, 2u)          // N
ST_UINT(kStSkipLevel, 3u)       // K: the octree level of the cells
ST_UINT(kStEntries, 4u)         // word offset of the cells' entries
ST_UINT(kStCellSlots, 5u)       // word offset of the cells' slot pointers
ST_UINT(kStLights, 6u)          // word offset of the slices' light spaces
ST_UINT(kStHeaderWords, 8u)     // then the K coarse-level offsets
ST_UINT(kStLightWords, 17u)     // origin, axis_u, axis_v, forward (f32 x3 each), near (f32), then:
ST_UINT(kStLightCentreU, 13u)   // f32: perspective lights: u = x / z + this (0 for an affine light)
ST_UINT(kStLightCentreV, 14u)   // f32: likewise v
ST_UINT(kStLightProjection, 15u)  // 0: affine (u = x, v = y), 1: perspective (x / z, y / z)
ST_UINT(kStLightSlopeCap, 16u)  // f32: the receiver plane's steepest slope per finest texel (st_plane.glsl)
ST_UINT(kMaxStackCells, 0x400000u)  // kStackMaxCells: cells < 2^22
ST_UINT(kStKindSplit, 2u)       // an entry's kind (low 8 bits): split (st::kStackSplit), answered by its children below
ST_UINT(kStFirstChildShift, 8u)  // a split entry's kind word: its first child's cell << this (cells < 2^22)
// A per-slice cell's tile (tiles/core/stack_slices.hpp "STSL"): a 4-word header, then per
// slice 2 words (byte offset of its 2D tile, 0: a constant; then the size or the f32 bits).
ST_UINT(kSlMagic, 0x4C535453u)     // "STSL"
ST_UINT(kSlHeaderWords, 4u)
ST_UINT(kSlEntryWords, 2u)
ST_UINT(kMmhMagic, 0x4D4D5453u)    // "STMM": an MMH tile where a DAG-MH one may be (PACK.md "Mixed tiles")

// ---- stack queries (binding kBindInput of stack_evaluate.comp) ----
ST_UINT(kSqWords, 7u)
ST_UINT(kSqX, 0u)             // texel x: of `level`, or of the finest level (kLevelFromFootprint)
ST_UINT(kSqY, 1u)
ST_UINT(kSqSlice, 2u)         // w
ST_UINT(kSqLevel, 3u)         // explicit level, or kLevelFromFootprint
ST_UINT(kSqReceiver, 4u)      // f32 light-space depth of the receiver in slice w
ST_UINT(kSqFootprint, 5u)     // f32 footprint in finest texels (kLevelFromFootprint only)
ST_UINT(kSqR, 6u)             // PCF kernel side 1..9; 0: answer the depth itself

// ---- queries (binding kBindInput of evaluate.comp) ----
ST_UINT(kQueryWords, 6u)
ST_UINT(kQueryX, 0u)          // texel x: of `level`, or of the finest level (kLevelFromFootprint)
ST_UINT(kQueryY, 1u)
ST_UINT(kQueryReceiver, 2u)   // f32 light-space depth of the receiver
ST_UINT(kQueryFootprint, 3u)  // f32 footprint in finest texels (kLevelFromFootprint only)
ST_UINT(kQueryR, 4u)          // PCF kernel side 1..9; 0: answer the depth itself
ST_UINT(kQueryLevel, 5u)      // explicit level, or kLevelFromFootprint
ST_UINT(kLevelFromFootprint, 0xFFFFFFFFu)

// ---- feedback buffer (binding kBindFeedback) ----
// header words, then kFbCapacity keys (0 = empty; a hash set), then one record per key,
// then the claimed keys' positions in claim order (kFbUsed of them): the host reads and
// clears only what a frame claimed.
ST_UINT(kFbUsed, 0u)        // keys claimed (and positions listed)
ST_UINT(kFbDropped, 1u)     // absent tiles that found no room (set full or probes exhausted)
ST_UINT(kFbHoles, 2u)       // queries/pixels answered from a coarser level
ST_UINT(kFbAbsentTaps, 3u)  // taps answered from a coarser level
ST_UINT(kFbCapacity, 4u)    // power of two, written by the host
ST_UINT(kFbHeaderWords, 8u)
ST_UINT(kFbRecordWords, 6u)
ST_UINT(kFbRecCount, 0u)      // pixels (or queries) that needed the tile
ST_UINT(kFbRecLevel, 1u)      // the tile's root: level, x, y (its id is make_tile_id of them)
ST_UINT(kFbRecX, 2u)
ST_UINT(kFbRecY, 3u)
ST_UINT(kFbRecValue, 4u)      // the page-table entry naming the tile: f32 value
ST_UINT(kFbRecKind, 5u)       //   and kind | index_levels << 8
ST_UINT(kFbMaxProbes, 32u)
// Keys name the entry that points at the absent tile: skip entry e -> e + 1; entry c of
// the index tile in slot s -> kFbChildKeyBit | (s * kChildTableWords + c).
ST_UINT(kFbChildKeyBit, 0x80000000u)
// A stack map's absent cell c -> kFbStackKeyBit | c (record: level K, x c, y 0).
ST_UINT(kFbStackKeyBit, 0x40000000u)
// An absent deep tile (tx, ty) of a deep map of level D, tiles 2^b a side ->
// kFbDeepKeyBit | ty << (D - b) | tx (record: level D, x tx, y ty, value 0, kind 0).
ST_UINT(kFbDeepKeyBit, 0x20000000u)

// ---- push constants (words) ----
ST_UINT(kPcCount, 0u)       // evaluate: queries; shadow pass: width
ST_UINT(kPcHeight, 1u)      // shadow pass: height
ST_UINT(kPcKernel, 2u)      // shadow pass: PCF kernel side 1..9
ST_UINT(kPcFlags, 3u)       // shadow pass: bit 0 per-pixel footprint from neighbours
ST_UINT(kPcOrigin, 4u)      // f32 x3: the light box's near-plane corner
ST_UINT(kPcAxisU, 7u)       // f32 x3: axis_u / extent
ST_UINT(kPcAxisV, 10u)      // f32 x3: axis_v / extent
ST_UINT(kPcForward, 13u)    // f32 x3: forward / (far - near)
ST_UINT(kPcNear, 16u)       // f32: near / (far - near)
ST_UINT(kPcNormalOffset, 17u)  // f32: world units along the normal
ST_UINT(kPcFootprint, 18u)  // f32: footprint when bit 0 of flags is clear
// The stack shadow pass reads its light spaces per slice from the stack block; in place of
// the light it takes the two slices and the time blend's weight (GpuMap::submit_shadow_pass).
ST_UINT(kPcSliceA, 4u)      // slice a = floor(time * (N - 1))
ST_UINT(kPcSliceB, 5u)      // slice a + 1, or a when the time is a sample's (answer: slice a alone)
ST_UINT(kPcTimeWeight, 6u)  // f32 f = time * (N - 1) - a, rounded once: va + f * (vb - va)
ST_UINT(kPcWords, 20u)
ST_UINT(kFlagNeighbourFootprint, 1u)
ST_UINT(kFlagSoft, 2u)      // stack shadow pass: the average over all N slices (slices a, b unused)
ST_UINT(kFlagResumeWalks, 4u)  // stack shadow pass: tile walks resume from the previous walk's path
ST_UINT(kFlagReceiverPlane, 8u)  // shadow passes: each PCF tap against the receiver's plane (st_plane.glsl)

// ---- the deep block (deep shadow maps, tiles/core/DEEP.md; GPU_LAYOUT.md "The deep block") ----
// At page word kPtDeep: a header, then `capacity` (key, word offset) pairs of the deep tiles
// the device holds, sorted by key = ty << (D - b) | tx (the first `count` used), then the
// tiles' words (each a deep tile, tiles/core/deep_format.hpp, as the client holds it).
ST_UINT(kDpLevel, 0u)           // D: the deep map's level; 0 until its directory arrives (all lit)
ST_UINT(kDpSideBits, 1u)        // b: deep tiles are 2^b texels a side
ST_UINT(kDpCount, 2u)           // tiles on the device (pairs used)
ST_UINT(kDpCapacity, 3u)        // pairs reserved
ST_UINT(kDpDepthBias, 4u)       // f32: the lookup point's move toward the light, in light-space depth
ST_UINT(kDpPresence, 5u)        // page word of the directory's bitmap (bit ty << (D - b) | tx: the tile
                                // exists), for feedback of absent deep tiles; 0: none (no deep feedback)
ST_UINT(kDpHeaderWords, 8u)
ST_UINT(kDeepQuery, 0xFFFFFFFEu)  // evaluate: kQueryR of a deep query (u, v, depth, width: GpuDeepQuery)
// A deep tile's own words (deep_format.hpp): a 12-word header, then 2 directory words per texel.
ST_UINT(kDtTexelCount, 5u)
ST_UINT(kDtHeaderWords, 12u)

// ---- bindings (descriptor set 0) ----
ST_UINT(kBindPool, 0u)
ST_UINT(kBindPage, 1u)
ST_UINT(kBindInput, 2u)     // evaluate: queries; shadow pass: positions (f32 x4 per pixel)
ST_UINT(kBindNormals, 3u)   // shadow pass: normals (f32 x4 per pixel)
ST_UINT(kBindOutput, 4u)    // f32 per query or pixel
ST_UINT(kBindFeedback, 5u)
ST_UINT(kWorkgroupSize, 64u)
ST_UINT(kProbeWords, 128u)  // layout_probe.comp writes this many words

#ifdef __cplusplus
}  // namespace st::gpu::layout
#endif
#undef ST_UINT
#endif
