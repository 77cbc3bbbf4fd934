// shadowtile GPU evaluators for stack maps (shadow-map stacks, MH 2016 §4): the MH octree
// tile decoder, per-slice cells (each slice's own 2D tile) and the walk of the stack block (the octree's top K levels, the level-K
// cells and split cells' children, gpu/GPU_LAYOUT.md "The stack block"), the same operations as the CPU's
// MhOctree::depth (tiles/core/mh_octree_reader.cpp) and StackMap::depth
// (tiles/core/stack_map.cpp), so every answer is bit-exact with the CPU's.
//
// Include after st_eval.glsl (it uses StProbe, st_lit, st_feedback, st_filter_levels and
// st_pcf_tap). Entry points: st_oct_depth(base, x, y, w, level) (one tile),
// st_oct_depth_resumed (the same answer, the walk resumed from the invocation's previous
// walk in that tile; st_oct_path_reset(resume) first, which also makes st_stack_depth use it),
// st_stack_depth(x, y, w, level, probe), st_stack_pcf(level, x, y, w, r, receiver, probe),
// st_stack_lookup(x, y, w, receiver, footprint, r, probe) (level from a footprint), their
// receiver-plane forms st_stack_pcf_plane and st_stack_lookup_plane, and
// st_fdiv(a, b) (st_fdiv.glsl: a / b rounded as the CPU's float division, for the passes' divides).
#ifndef SHADOWTILE_GPU_ST_STACK_GLSL
#define SHADOWTILE_GPU_ST_STACK_GLSL

#include "st_fdiv.glsl"

// A cell's tile is an MH octree ("STOC") or per-slice 2D tiles ("STSL"), told by its magic.

// ---- MH octree tiles (tiles/core/MHOCT.md) ----
// Texel (x, y) of the level-`level` map of slice w of the octree at pool word `base`
// (level <= its xy_level n, x, y < 2^level, w < its slices: the caller checks, as
// StackMap::depth does before it asks a tile). Header words: 1 = version | n << 16 |
// k << 24; 2 = slices | flags << 16; bytes 20.. the per-level shifts; the tree follows at
// byte 20 + round_up(max(n, k) + 1, 4).
uint st_oct_xy_bits(uint l, uint n, uint depth) { return l + n >= depth ? l + n - depth : 0u; }

// One step of a walk towards texel (x, y) of slice w at `level`, from the node at tree word
// `pos` of octree level l: returns the child's code (0 missing, 1 leaf, 2 inner without a
// value, 3 inner with one) and, unless 0, moves pos to the child's word.
uint st_oct_step(uint base, uint tree, uint n, uint k, uint depth, uint l, uint x, uint y, uint w, uint level,
                 inout uint pos) {
  uint slot = 0u;
  if (l + n >= depth) {  // the step halves x and y: their bits at the child's resolution
    const uint b = level - st_oct_xy_bits(l + 1u, n, depth);
    slot = ((x >> b) & 1u) | (((y >> b) & 1u) << 1u);
  }
  if (l + k >= depth) slot |= ((w >> (k - st_oct_xy_bits(l + 1u, k, depth))) & 1u) << 2u;  // halves w
  const uint word = ST_POOL(tree + pos);
  const uint mask = word & 0xFFFFu;
  const uint code = (mask >> (2u * slot)) & 3u;
  if (code == 0u) return 0u;
  const uint shift = st_byte(base, 20u + l);
  // off: a signed 16-bit number (negative = an equal block laid out earlier); uint
  // arithmetic wraps as the CPU's block_start does. Version 3: off < -32736 is far, the
  // block's tree word is the far word at pos + 1 + (off + 32768) (moct::child_block).
  const int off = int(word) >> 16;
  const uint block = off < -32736 ? ST_POOL(tree + pos + 1u + uint(off + 32768)) : ((pos >> shift) + uint(off)) << shift;
  pos = block + uint(bitCount(mask & ((1u << (2u * slot)) - 1u)));
  return code;
}

// shift: the square of texels of the same slice (x >> shift, y >> shift equal) that get the
// same answer: the node the walk ended at (a leaf, or the missing child: every texel under it
// takes the same path to the same last valued node), 0 when it reached `level`.
float st_oct_depth(uint base, uint x, uint y, uint w, uint level, out uint shift) {
  const uint h1 = ST_POOL(base + 1u), h2 = ST_POOL(base + 2u);
  const uint n = (h1 >> 16u) & 0xFFu, k = h1 >> 24u;
  const bool root_leaf = ((h2 >> 16u) & 1u) != 0u;
  const uint depth = max(n, k);
  const uint tree = base + 5u + ((depth + 4u) >> 2u);  // 20 bytes + round_up(depth + 1, 4)
  const uint target = level + depth - n;              // Geometry::level_of_xy
  uint pos = 0u;
  uint val = root_leaf ? 0u : 1u;
  uint code = root_leaf ? 1u : 3u;
  uint l = 0u;
  for (; l < target && code != 1u; ++l) {
    code = st_oct_step(base, tree, n, k, depth, l, x, y, w, level, pos);
    if (code == 0u) break;  // missing child: the last valued node answers
    if (code != 2u) val = code == 1u ? pos : pos + 1u;
  }
  shift = level - st_oct_xy_bits(code == 0u ? l + 1u : l, n, depth);  // the node the walk ended at
  return uintBitsToFloat(ST_POOL(tree + val));
}
float st_oct_depth(uint base, uint x, uint y, uint w, uint level) {
  uint shift;
  return st_oct_depth(base, x, y, w, level, shift);
}

// ---- resumed walks (MH 2016 §3.3's last-sample cache, carried over w) ----
// st_oct_depth_resumed answers as st_oct_depth, but starts from the deepest node its path
// shares with the previous resumed walk in the same tile, as MhOctree::along_begin does on
// the CPU: nodes of level l lie on both paths iff the finest-texel x, y agree above bit
// D - l and w above bit D - l (D = max(n, k) of the tile; the tile's geometry makes both
// thresholds the same), so the walk restarts at level min(D - bit_width(x ^ x'),
// D - bit_width(w ^ w'), where the previous walk ended, its own target). A walk to a
// coarser level compares its texel's first finest descendant (the nodes above its target
// are the same). The path is per invocation (private variables): a pass that walks many
// coherent texels (a soft pass's slices in order, a PCF kernel's taps) reads only the
// nodes where consecutive paths part. st_oct_path_reset(resume) forgets the path and
// says whether st_stack_depth resumes (off until a kernel turns it on).
const uint kStOctPathLevels = 21u;  // moct::kMaxLevels: octree levels 0..20 of a tile
const uint kStOctPathLeaf = 0x80000000u;  // st_oct_path_val's flag: the node is a leaf
uint st_oct_path_base = kNoSlot;  // pool word of the tile the previous walk read; kNoSlot: none
uint st_oct_path_x, st_oct_path_y, st_oct_path_w, st_oct_path_reached;
uint st_oct_path_pos[kStOctPathLevels];  // per level: the node's tree word
uint st_oct_path_val[kStOctPathLevels];  // the last valued node's float word, | kStOctPathLeaf
bool st_oct_resume = false;  // st_stack_depth walks tiles with st_oct_depth_resumed

void st_oct_path_reset(bool resume) {
  st_oct_path_base = kNoSlot;
  st_oct_resume = resume;
}

float st_oct_depth_resumed(uint base, uint x, uint y, uint w, uint level, out uint shift) {
  const uint h1 = ST_POOL(base + 1u);
  const uint n = (h1 >> 16u) & 0xFFu, k = h1 >> 24u;
  const uint depth = max(n, k);
  const uint tree = base + 5u + ((depth + 4u) >> 2u);
  const uint target = level + depth - n;
  const uint fx = x << (n - level), fy = y << (n - level);  // level <= n
  uint l = 0u;
  if (st_oct_path_base == base) {
    const uint hx = uint(findMSB((fx ^ st_oct_path_x) | (fy ^ st_oct_path_y)) + 1);
    const uint hw = uint(findMSB(w ^ st_oct_path_w) + 1);
    l = min(min(depth - min(depth, hx), depth - min(depth, hw)), min(st_oct_path_reached, target));
  } else {
    const bool root_leaf = ((ST_POOL(base + 2u) >> 16u) & 1u) != 0u;
    st_oct_path_pos[0] = 0u;
    st_oct_path_val[0] = root_leaf ? kStOctPathLeaf : 1u;
  }
  uint pos = st_oct_path_pos[l];
  uint val = st_oct_path_val[l];
  uint code = (val & kStOctPathLeaf) != 0u ? 1u : 3u;  // only "leaf or not" matters here
  val &= ~kStOctPathLeaf;
  for (; l < target && code != 1u; ++l) {
    code = st_oct_step(base, tree, n, k, depth, l, x, y, w, level, pos);
    if (code == 0u) break;  // missing child: the walk ends at level l
    if (code != 2u) val = code == 1u ? pos : pos + 1u;
    st_oct_path_pos[l + 1u] = pos;
    st_oct_path_val[l + 1u] = code == 1u ? val | kStOctPathLeaf : val;
  }
  st_oct_path_base = base;
  st_oct_path_x = fx;
  st_oct_path_y = fy;
  st_oct_path_w = w;
  st_oct_path_reached = l;
  shift = level - st_oct_xy_bits(code == 0u ? l + 1u : l, n, depth);  // as st_oct_depth's
  return uintBitsToFloat(ST_POOL(tree + val));
}
float st_oct_depth_resumed(uint base, uint x, uint y, uint w, uint level) {
  uint shift;
  return st_oct_depth_resumed(base, x, y, w, level, shift);
}

// ---- per-slice cells (tiles/core/stack_slices.hpp "STSL") ----
// Texel (x, y) of the level-`level` map of slice w of the per-slice cell at pool word `base`
// (level <= its xy_level, w < its 2^w_level entries: the caller checks): entry w's first word
// is the byte offset of the slice's own 2D tile (4-aligned), 0 for a constant slice whose f32
// bits are the second word; the tile is DAG-MH, or MMH by its magic, as st_tile_depth reads a
// DAG-MH pack's mixed tiles, or a plane tile ("STPN") over either, read as st_tile_depth
// reads one (st_plane_lookup, then the inner buffer). The same answer as SliceTiles::depth.
float st_slices_depth(uint base, uint x, uint y, uint w, uint level) {
  const uint e = base + kSlHeaderWords + kSlEntryWords * w;
  const uint off = ST_POOL(e);
  if (off == 0u) return uintBitsToFloat(ST_POOL(e + 1u));
  uint tile = base + (off >> 2u);
  if (ST_POOL(tile) == 0x4E505453u) {  // "STPN": plane blocks over a DAG-MH or MMH buffer (st_tile_depth's)
    float d;
    if (st_plane_lookup(tile, level, x, y, d)) return d;
    tile += 6u + 6u * ST_POOL(tile + 4u) + 2u * ST_POOL(tile + 2u) + 6u * ST_POOL(tile + 5u);
  }
  if (ST_POOL(tile) == kMmhMagic) return st_mh_depth(tile, level, x, y, true);
  return st_dag_depth(tile, level, x, y);
}

// ---- the stack block's walk (StackMap::depth over the GPU's copy of the cache) ----
// Texel (x, y) of the level-`level` map of slice w. Out of range: lit. Levels above K
// read the dense coarse values; from K down, the cell is level K's, then down split cells
// (a version-2 grid: entry kind kStKindSplit, its children from the cell in its kind word's
// upper bits) while above the level read, as StackGrid::cell_at; a constant cell, or one at
// that level, answers its entry's value; a cell whose tile is not on the GPU answers its
// entry's value (its level's map: coarser, never missing) and is recorded in the feedback.
// shift: the square of texels of slice w (x >> shift, y >> shift equal) that get the same
// answer (st_answer's for 2D maps): a constant cell's, an octree walk's node, a constant
// slice's cell; 0 for a dense coarse value, an absent tile (fed back per texel, as before)
// and a per-slice 2D tile.
float st_stack_depth(uint x, uint y, uint w, uint level, inout StProbe probe, out uint shift) {
  const uint blk = ST_PAGE(kPtStack);
  const uint n = ST_PAGE(blk + kStXyLevel), k = ST_PAGE(blk + kStWLevel);
  shift = level;
  if (level > n || w >= ST_PAGE(blk + kStSlices) || (x >> level) != 0u || (y >> level) != 0u)
    return uintBitsToFloat(kLitDepthBits);
  shift = 0u;
  const uint K = ST_PAGE(blk + kStSkipLevel);
  const uint depth = max(n, k);
  const uint T = level + depth - n;  // the octree level with 2^level texels a side
  uint l = min(T, K);                // the node's level: T above K, else the cell's
  uint a = st_oct_xy_bits(l, n, depth), b = st_oct_xy_bits(l, k, depth);
  uint index = (((((w >> (k - b)) << a) + (y >> (level - a))) << a) + (x >> (level - a)));
  if (T < K) return uintBitsToFloat(ST_PAGE(ST_PAGE(blk + kStHeaderWords + T) + index));
  const uint entries = ST_PAGE(blk + kStEntries);
  uint kind_word = ST_PAGE(entries + kEntryWords * index + 1u);
  while (l < T && (kind_word & 0xFFu) == kStKindSplit) {  // down a split cell: its child over (x, y, w)
    const uint dx = l + n >= depth ? 1u : 0u, dw = l + k >= depth ? 1u : 0u;  // the step halves x, y / w
    ++l;
    a = st_oct_xy_bits(l, n, depth);
    b = st_oct_xy_bits(l, k, depth);
    const uint ox = (x >> (level - a)) & dx, oy = (y >> (level - a)) & dx, ow = (w >> (k - b)) & dw;
    index = (kind_word >> kStFirstChildShift) + ((((ow << dx) + oy) << dx) + ox);
    kind_word = ST_PAGE(entries + kEntryWords * index + 1u);
  }
  const uint value_bits = ST_PAGE(entries + kEntryWords * index);
  const uint rel = level - a;  // the cell's (the tile's own) x, y level
  if ((kind_word & 0xFFu) != kKindTile || T == l) {
    shift = rel;  // the cell's value holds for its square
    return uintBitsToFloat(value_bits);
  }
  const uint slot = ST_PAGE(ST_PAGE(blk + kStCellSlots) + index);
  if (slot == kNoSlot) {
    st_feedback(kFbStackKeyBit | index, l, index, 0u, value_bits, kKindTile, probe);
    return uintBitsToFloat(value_bits);
  }
  const uint cx = x >> rel, cy = y >> rel, cw = w >> (k - b);
  const uint tile = slot * ST_PAGE(kPtSlotWords), tx = x - (cx << rel), ty = y - (cy << rel), tw = w - (cw << (k - b));
  if (ST_POOL(tile) == kSlMagic) {  // a per-slice cell; a constant slice holds for the cell's square
    if (ST_POOL(tile + kSlHeaderWords + kSlEntryWords * tw) == 0u) shift = rel;
    return st_slices_depth(tile, tx, ty, tw, rel);
  }
  return st_oct_resume ? st_oct_depth_resumed(tile, tx, ty, tw, rel, shift) : st_oct_depth(tile, tx, ty, tw, rel, shift);
}
float st_stack_depth(uint x, uint y, uint w, uint level, inout StProbe probe) {
  uint shift;
  return st_stack_depth(x, y, w, level, probe, shift);
}

// r x r PCF in slice w (StackMap::filtered's kernel: lit taps / (r * r), taps clamped to
// the slice's edges; the quotient from the host's table, as st_pcf), each tap compared with
// the receiver's plane (corner, gx, gy) over the tap's texel (tiles/core/receiver_plane.hpp,
// StackMap::filtered_on_plane; st_plane_depth: f the receiver's texel of the slice's finest
// level `finest`). Zero slopes: one receiver depth, the corner (st_stack_pcf).
// Taps counted in blocks as st_pcf_plane counts a 2D map's (MH §3.3's hierarchical PCF): a
// tap's answer holds for the square st_stack_depth's shift names, so every kernel tap in it
// counts with it (st_pcf_block: at once where the plane decides the block, else one by one)
// and the next descent starts at the first tap not counted: a kernel inside one constant
// cell or octree leaf costs one descent. The count is the per-tap count: the CPU's answer.
float st_stack_pcf_plane(uint level, uint x, uint y, uint w, uint r, vec3 plane, uvec2 f, uint finest,
                         inout StProbe probe) {
  r = clamp(r, 1u, kMaxPcf);
  const uint side = 1u << min(level, 31u), taps = r * r;
  uint lit = 0u, done0 = 0u, done1 = 0u, done2 = 0u;
  for (uint k = 0u; k < taps; k = st_pcf_next(done0, done1, done2)) {  // one descent a pass
    const uint j = k / r, i = k - j * r;
    uint shift;
    const float value = st_stack_depth(st_pcf_tap(x, i, r, side), st_pcf_tap(y, j, r, side), w, level, probe, shift);
    shift = min(shift, level);
    st_pcf_block(x, y, r, side, i, j, st_pcf_run(x, i, r, side, shift), st_pcf_run(y, j, r, side, shift), value, plane,
                 f, finest - level, lit, done0, done1, done2);
  }
  return uintBitsToFloat(ST_PAGE(ST_PAGE(kPtPcfTable) + (r - 1u) * kPcfTableStride + lit));
}
float st_stack_pcf(uint level, uint x, uint y, uint w, uint r, float receiver, inout StProbe probe) {
  return st_stack_pcf_plane(level, x, y, w, r, vec3(receiver, 0.0, 0.0), uvec2(0u), level, probe);
}

// (x, y): the receiver's texel of slice w's finest level; the two levels from the footprint
// (in finest texels), r x r PCF at each against the receiver plane (corner, gx, gy),
// blended (a + t * (c - a), each step rounded once) as st_lookup_plane does for 2D maps.
// One call site of st_stack_pcf_plane for both levels: a shader compiler inlines the walk once.
float st_stack_lookup_plane(uint x, uint y, uint w, vec3 plane, float footprint, uint r, inout StProbe probe) {
  const uint finest = ST_PAGE(ST_PAGE(kPtStack) + kStXyLevel);
  const StFilter f = st_filter_levels(footprint, finest);
  float a = 0.0, c = 0.0;
  for (uint k = 0u; k < (f.t == 0.0 ? 1u : 2u); ++k) {
    const uint l = k == 0u ? f.fine : f.coarse;
    const float v = st_stack_pcf_plane(l, x >> (finest - l), y >> (finest - l), w, r, plane, uvec2(x, y), finest, probe);
    if (k == 0u) a = v;
    else c = v;
  }
  if (f.t == 0.0) return a;
  precise float step = c - a;
  precise float scaled = f.t * step;
  precise float blended = a + scaled;
  return blended;
}
// The same with one receiver depth for every tap (StackMap::filtered).
float st_stack_lookup(uint x, uint y, uint w, float receiver, float footprint, uint r, inout StProbe probe) {
  return st_stack_lookup_plane(x, y, w, vec3(receiver, 0.0, 0.0), footprint, r, probe);
}

#endif
