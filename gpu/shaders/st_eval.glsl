// shadowtile GPU evaluators: the page-table walk over the GPU tile cache and the MH, MMH
// DAG-MH and voxel shadow DAG tile decoders, the same operations as the CPU's (tiles/core/page_table.hpp,
// mh_quadtree_reader.cpp, dagmh_traverse.hpp, dagmh_values.hpp, client/remote_map_lookups.cpp),
// so every answer is bit-exact with the CPU's (gpu/GPU_LAYOUT.md "Exactness").
//
// An engine includes this file in its own compute or fragment shader. Before including
// it, define three accessors over its buffers (arrays of uint) and include st_layout.h:
//   #define ST_POOL(w) my_pool[w]      // the slot pool (slot s at word s * slot_words)
//   #define ST_PAGE(w) my_page[w]      // the page-table buffer
//   #define ST_FB(w)   my_feedback[w]  // the feedback buffer (read-write, atomics)
//   #define ST_POOL4(q) my_pool_quads[q] // optional: the same pool as uvec4 quads (words 4q..4q+3)
// Entry points: st_depth(level, x, y, probe), st_pcf(level, x, y, r, receiver, probe),
// st_lookup(x, y, receiver, footprint, r, probe) (level from a footprint, MH §3.3), and
// st_pcf_plane / st_lookup_plane (a receiver plane per tap: tiles/core/receiver_plane.hpp).
#ifndef SHADOWTILE_GPU_ST_EVAL_GLSL
#define SHADOWTILE_GPU_ST_EVAL_GLSL

// What one query or pixel needed and did not find: the last absent entry it recorded
// (so a pixel counts once per tile) and whether any tap was answered coarsely.
struct StProbe {
  uint last_key;
  bool hole;
};

StProbe st_probe() {
  StProbe p;
  p.last_key = 0u;
  p.hole = false;
  return p;
}

// ---- the lit test, in integers ----
// receiver <= value as IEEE binary32 compares it, on the bit patterns: a device that
// flushes subnormals in float compares (no shaderDenormPreserveFloat32) still answers
// like the CPU. NaN on either side is not lit; -0 == +0.
int st_order(uint b) {
  return (b & 0x80000000u) != 0u ? -int(b & 0x7FFFFFFFu) : int(b);
}
bool st_lit(float receiver, float value) {
  const uint rb = floatBitsToUint(receiver), vb = floatBitsToUint(value);
  if ((rb & 0x7FFFFFFFu) > 0x7F800000u || (vb & 0x7FFFFFFFu) > 0x7F800000u) return false;
  return st_order(rb) <= st_order(vb);
}

// ---- feedback (sparse virtual texturing style): absent tiles into a hash set ----
// With ST_NO_FEEDBACK defined (shadowtile.glsl's ST_FEEDBACK 0) nothing is written and no
// ST_FB accessor is needed: the probe still says whether a tap answered coarsely.
#ifdef ST_NO_FEEDBACK
void st_feedback(uint key, uint level, uint ex, uint ey, uint value_bits, uint kind_word, inout StProbe probe) {
  probe.hole = true;
}
#else
void st_feedback(uint key, uint level, uint ex, uint ey, uint value_bits, uint kind_word, inout StProbe probe) {
  probe.hole = true;
  atomicAdd(ST_FB(kFbAbsentTaps), 1u);
  if (probe.last_key == key) return;
  probe.last_key = key;
  const uint cap = ST_FB(kFbCapacity);
  uint h = (key * 0x9E3779B1u) & (cap - 1u);
  for (uint i = 0u; i < kFbMaxProbes; ++i) {
    const uint old = atomicCompSwap(ST_FB(kFbHeaderWords + h), 0u, key);
    const uint rec = kFbHeaderWords + cap + h * kFbRecordWords;
    if (old == 0u) {  // this invocation claimed the key: it lists it and writes the record
      const uint n = atomicAdd(ST_FB(kFbUsed), 1u);  // < cap: one claim per empty key word
      ST_FB(kFbHeaderWords + cap * (1u + kFbRecordWords) + n) = h;
      ST_FB(rec + kFbRecLevel) = level;
      ST_FB(rec + kFbRecX) = ex;
      ST_FB(rec + kFbRecY) = ey;
      ST_FB(rec + kFbRecValue) = value_bits;
      ST_FB(rec + kFbRecKind) = kind_word;
      atomicAdd(ST_FB(rec + kFbRecCount), 1u);
      return;
    }
    if (old == key) {
      atomicAdd(ST_FB(rec + kFbRecCount), 1u);
      return;
    }
    h = (h + 1u) & (cap - 1u);
  }
  atomicAdd(ST_FB(kFbDropped), 1u);
}
#endif

// ---- small helpers ----
uint st_coarse_index(uint level) { return ((1u << (2u * level)) - 1u) / 3u; }

// ---- runs of pool words ----
// With ST_POOL4(q) defined (the same pool as uvec4 quads: words 4q..4q+3; shadowtile.glsl and
// st_buffers.glsl declare it), a run of up to 4 (5, 8) words is read as the 2 (2, 3) aligned quads
// that hold it: a device that compiles each buffer read to a loop over its lanes (llvmpipe)
// runs one such loop per quad, not one per word. Every quad read holds a word of the run, and
// GpuMap's pool is a whole number of quads (its slots are), so no read leaves the buffer.
// Without ST_POOL4 (texel buffers, an engine's own accessors) the words are read one by one.
#ifdef ST_POOL4
uvec4 st_quad_shift(uvec4 a, uvec4 b, uint o) {  // words o..o+3 of the eight words (a, b)
  return o == 0u ? a : o == 1u ? uvec4(a.yzw, b.x) : o == 2u ? uvec4(a.zw, b.xy) : uvec4(a.w, b.xyz);
}
// Words w..w+n-1 (n in 1..4) in the first n components (the others: any words).
uvec4 st_pool_run(uint w, uint n) {
  return st_quad_shift(ST_POOL4(w >> 2u), ST_POOL4((w + n - 1u) >> 2u), w & 3u);
}
// Words w..w+3 in `lo`, w+4 in `e`.
void st_pool_run5(uint w, out uvec4 lo, out uint e) {
  const uvec4 a = ST_POOL4(w >> 2u), b = ST_POOL4((w >> 2u) + 1u);
  const uint o = w & 3u;
  lo = st_quad_shift(a, b, o);
  e = o == 0u ? b.x : o == 1u ? b.y : o == 2u ? b.z : b.w;
}
// Words w..w+3 in `lo`, w+4..w+n-1 (n in 5..8) in `hi`'s first n - 4 components.
void st_pool_run8(uint w, uint n, out uvec4 lo, out uvec4 hi) {
  const uvec4 a = ST_POOL4(w >> 2u), b = ST_POOL4((w >> 2u) + 1u), c = ST_POOL4((w + n - 1u) >> 2u);
  lo = st_quad_shift(a, b, w & 3u);
  hi = st_quad_shift(b, c, w & 3u);
}
#else
uvec4 st_pool_run(uint w, uint n) {
  return uvec4(ST_POOL(w), n > 1u ? ST_POOL(w + 1u) : 0u, n > 2u ? ST_POOL(w + 2u) : 0u, n > 3u ? ST_POOL(w + 3u) : 0u);
}
void st_pool_run5(uint w, out uvec4 lo, out uint e) {
  lo = uvec4(ST_POOL(w), ST_POOL(w + 1u), ST_POOL(w + 2u), ST_POOL(w + 3u));
  e = ST_POOL(w + 4u);
}
void st_pool_run8(uint w, uint n, out uvec4 lo, out uvec4 hi) {
  lo = uvec4(ST_POOL(w), ST_POOL(w + 1u), ST_POOL(w + 2u), ST_POOL(w + 3u));
  hi = uvec4(ST_POOL(w + 4u), n > 5u ? ST_POOL(w + 5u) : 0u, n > 6u ? ST_POOL(w + 6u) : 0u, n > 7u ? ST_POOL(w + 7u) : 0u);
}
#endif
uint st_byte(uint base_word, uint byte_offset) {
  return (ST_POOL(base_word + (byte_offset >> 2u)) >> (8u * (byte_offset & 3u))) & 0xFFu;
}

// ---- MH and MMH tiles (MH §3.2; tiles/core/MHQUAD.md) ----
// The depth of texel (x, y) of `level` and in `shift` the square of texels that share it
// (those with the same x >> shift, y >> shift): a walk that ends above `level` at a leaf or
// a missing child ends there for every texel under that node, with the same value.
// The tree's first word and the root's value (st_mh_depth_at's hdr and root, read once a tile).
uint st_mh_tree(uint base, uint hdr) { return base + 4u + ((((hdr >> 16u) & 0xFFu) + 3u) >> 2u); }
uint st_mh_root(uint base, uint hdr) { return ST_POOL(st_mh_tree(base, hdr) + (((hdr >> 24u) & 1u) != 0u ? 0u : 1u)); }
// st_mh_depth with the tile's header word 1 (hdr) and its root's value bits (root) given.
float st_mh_depth_at(uint base, uint hdr, uint root, uint level, uint x, uint y, bool relative, out uint shift) {
  level = min(level, kMaxMapLevel);
  const bool root_leaf = ((hdr >> 24u) & 1u) != 0u;
  const uint tree = st_mh_tree(base, hdr);
  uint pos = 0u;
  uint code = root_leaf ? 1u : 3u;
  uint val_pos = root_leaf ? 0u : 1u;
  precise float value = uintBitsToFloat(root);
  uint l = 0u, end = level;  // end: the level of the node whose texels share the answer
  while (l < level && code != 1u) {
    const uint bit = level - (l + 1u);
    const uint slot = ((x >> bit) & 1u) | (((y >> bit) & 1u) << 1u);
    const uint w = ST_POOL(tree + pos);
    const uint mask = w & 0xFFu;
    const uint child_code = (mask >> (2u * slot)) & 3u;
    if (child_code == 0u) {  // missing child: the last valued node answers every texel under it
      end = l + 1u;
      break;
    }
    const uint shift = relative ? ((w >> 12u) & 0xFu) : st_byte(base, 16u + l);
    const uint child = (((pos >> shift) + (w >> 16u)) << shift) + uint(bitCount(mask & ((1u << (2u * slot)) - 1u)));
    pos = child;
    code = child_code;
    l += 1u;
    if (code != 2u) {
      const uint vp = code == 1u ? child : child + 1u;
      if (relative) {
        const float s = uintBitsToFloat(ST_POOL(tree + vp));
        // mmh_add: one binary32 addition, nothing contracted into it
        value = ((w >> (8u + slot)) & 1u) != 0u ? s : value + s;
      } else {
        val_pos = vp;
      }
    }
  }
  if (code == 1u) end = l;  // a leaf (a missing child's break leaves code != 1)
  shift = level - end;
  return relative ? value : uintBitsToFloat(ST_POOL(tree + val_pos));
}
float st_mh_depth(uint base, uint level, uint x, uint y, bool relative, out uint shift) {
  const uint hdr = ST_POOL(base + 1u);
  return st_mh_depth_at(base, hdr, st_mh_root(base, hdr), level, x, y, relative, shift);
}
float st_mh_depth(uint base, uint level, uint x, uint y, bool relative) {
  uint shift;
  return st_mh_depth(base, level, x, y, relative, shift);
}

// ---- DAG-MH tiles (DAG-MH §3.5 Alg. 1, §3.4 Alg. 2; tiles/core/DAGMH.md) ----
struct StDagCursor {
  uint ref, level, base, last;
};

float st_dag_value(uint base, uint chunks, uint mults, uint index) {
  const uint c = chunks + (index / 32u) * 5u;
  const uint bit = index % 32u;
  uvec4 info;  // the chunk's words: value, mask, c_l, c_f; then packed
  uint packed;
  st_pool_run5(c, info, packed);
  const uint mask = info.y;
  if (((mask >> bit) & 1u) == 0u) return uintBitsToFloat(info.x);
  const uint code = packed >> 27u;
  const uint k = code == 31u ? 32u : code;
  const uint rank = uint(bitCount(mask & ((1u << bit) - 1u)));
  const uint pos = (packed & 0x7FFFFFFu) + rank * k;
  const uint wi = pos >> 5u, s = pos & 31u;
  uint i = ST_POOL(mults + wi) >> s;
  if (s != 0u) i |= ST_POOL(mults + wi + 1u) << (32u - s);
  if (k == 32u) return uintBitsToFloat(i);
  i &= (1u << k) - 1u;
  const float c_l = uintBitsToFloat(info.z);
  const float c_f = uintBitsToFloat(info.w);
  // affine_value: the product rounded to float, then the sum; `precise` forbids the fma
  precise float product = c_f * float(i);
  precise float v = c_l + product;
  return v;
}

// Tiles with the dictionary flag (tiles/core/DAGMH.md "Dictionary") address [the pack dictionary's
// nodes | their own] as one space, and likewise treelets: index i < D (T) reads the
// dictionary block (in the pool after the slots, at the pool word kPtDictionary names), else
// the tile's own i - D (t - T), the compare View::node_at / treelet_at make. A node lies
// wholly on one side, so its words n + k are on the side of n. Both sides are pool words, so
// a word is one read at a chosen address (one buffer read per word on a device that loops
// over lanes per read site, as llvmpipe does). Tiles without the flag have D = T = 0.
struct StDagSpace {
  uint nodes, treelets;    // the tile's sections (pool words)
  uint dnodes, dtreelets;  // the dictionary's (pool words)
  uint d, t;               // D node words, T treelets
};

uint st_dag_node_word(StDagSpace s, uint i) {
  return ST_POOL(i < s.d ? s.dnodes + i : s.nodes + (i - s.d));
}

// A treelet's three bitmap words.
uvec3 st_dag_treelet(StDagSpace s, uint t) {
  return st_pool_run(t < s.t ? s.dtreelets + t * 3u : s.treelets + (t - s.t) * 3u, 3u).xyz;
}

// Whether any of bits [lo, hi) of a treelet's 96-bit bitmap (w0, w1, w2) is set.
uint st_bit_span(uint lo, uint hi, uint at) {  // the bits of [lo, hi) in the word of bits [at, at + 32)
  const uint a = clamp(lo, at, at + 32u) - at, b = clamp(hi, at, at + 32u) - at;
  return (b >= 32u ? 0xFFFFFFFFu : (1u << b) - 1u) & ~(a >= 32u ? 0xFFFFFFFFu : (1u << a) - 1u);
}
bool st_treelet_any(uint w0, uint w1, uint w2, uint lo, uint hi) {
  return ((w0 & st_bit_span(lo, hi, 0u)) | (w1 & st_bit_span(lo, hi, 32u)) | (w2 & st_bit_span(lo, hi, 64u))) != 0u;
}

// The depth of texel (x, y) of `level` and in `shift` the square of texels that share its
// value index (those with the same x >> shift, y >> shift), as View::finish_region finds
// it: below a missing child every texel; at an inner node of `level` the texel alone; in a
// treelet the shallowest node on the path at or below the one that answered whose subtree
// holds no set bit besides its own (its deepest level the query reaches: the node alone).
// A DAG-MH tile's header decoded (st_dag_open): what st_dag_depth_in reads per texel, so
// that a PCF kernel's taps in one tile decode it once.
struct StDagTile {
  uint base, finest, skip_level, skip_words, chunk_words, mult_words, root;
  StDagSpace sp;
};

StDagTile st_dag_open(uint base) {
  // Header version 3 (DAGMH.md): word 2 = finest_level | skip_level << 8 | flags << 16;
  // the sections follow from the counts (dagmh::sections_of).
  StDagTile t;
  t.base = base;
  uvec4 h;  // header words 2..5 (flags and levels, root, node words, treelets); then 6 (values)
  uint values;
  st_pool_run5(base + 2u, h, values);
  const uint w2 = h.x;
  t.root = h.y;
  t.finest = w2 & 0xFFu;
  t.skip_level = (w2 >> 8u) & 0xFFu;
  t.skip_words = base + 8u;
  t.sp.nodes = t.skip_words + (t.skip_level == 0u ? 0u : 4u << (2u * t.skip_level));  // S = 0: no table
  t.sp.treelets = t.sp.nodes + h.z;
  t.chunk_words = t.sp.treelets + 3u * h.w;
  t.mult_words = t.chunk_words + 5u * ((values + 31u) / 32u);
  t.sp.d = 0u;
  t.sp.t = 0u;
  t.sp.dnodes = 0u;
  t.sp.dtreelets = 0u;
  if (((w2 >> 16u) & 1u) != 0u) {  // flag dictionary: opened by the client against the dictionary GpuMap uploaded
    const uint dict = ST_PAGE(kPtDictionary);  // a pool word
    const uvec4 dh = st_pool_run(dict + kDictNodeWords, 2u);  // D, T
    t.sp.d = dh.x;
    t.sp.t = dh.y;
    t.sp.dnodes = dict + kDictHeaderWords;
    t.sp.dtreelets = t.sp.dnodes + t.sp.d;
  }
  return t;
}

float st_dag_depth_in(StDagTile t, uint level, uint x, uint y, out uint shift) {
  const uint base = t.base, finest = t.finest, skip_level = t.skip_level, skip_words = t.skip_words;
  const uint chunk_words = t.chunk_words, mult_words = t.mult_words;
  const StDagSpace sp = t.sp;
  shift = 0u;
  if (level > finest) {
    const uint sh = level - finest;
    x >>= sh;
    y >>= sh;
    level = finest;
    shift = sh;  // texels below the tile's finest level share its texel's answer
  }
  const uint top = (1u << level) - 1u;
  x = min(x, top);
  y = min(y, top);
  StDagCursor c;
  if (skip_level > 0u && level >= skip_level) {
    const uint sh = level - skip_level;
    const uvec4 e = st_pool_run(skip_words + 4u * (((y >> sh) << skip_level) + (x >> sh)), 4u);
    c.ref = e.x;
    c.level = e.y;
    c.base = e.z;
    c.last = e.w;
  } else {
    c.ref = t.root;
    c.level = 0u;
    c.base = 0u;
    c.last = 0u;
  }
  // descend (dagmh_traverse.hpp View::descend)
  while ((c.ref & 0xC0000000u) == 0x40000000u && c.level < level) {
    const uint node = c.ref & 0x3FFFFFFFu;
    const uint flags = st_dag_node_word(sp, node);
    if ((flags & 0x100u) != 0u) c.last = c.base;
    const uint sh = level - c.level - 1u;
    const uint child = ((x >> sh) & 1u) | (((y >> sh) & 1u) << 1u);
    c.level += 1u;
    if (((flags >> child) & 1u) == 0u) {
      c.ref = 0u;
      break;
    }
    const uint rank = uint(bitCount(flags & 0xFu & ((1u << child) - 1u)));
    const uint entry = node + 1u + 2u * rank;
    c.base += st_dag_node_word(sp, entry + 1u);
    c.ref = st_dag_node_word(sp, entry) | (((flags >> (4u + child)) & 1u) != 0u ? 0x80000000u : 0x40000000u);
  }
  // finish
  uint index = c.last;
  const uint tag = c.ref & 0xC0000000u;
  if (tag == 0x40000000u) {  // an inner node of `level`: the texel alone
    index = (st_dag_node_word(sp, c.ref & 0x3FFFFFFFu) & 0x100u) != 0u ? c.base : c.last;
  } else if (tag != 0x80000000u) {  // the missing child at c.level: every texel under it
    shift += level - c.level;
  } else {
    const uint t = c.ref & 0x3FFFFFFFu;
    const uvec3 tw = st_dag_treelet(sp, t);
    const uint w0 = tw.x, w1 = tw.y, w2 = tw.z;
    const uint depth = min(level - c.level, 3u);
    uint p[4];
    p[0] = 0u;
    for (uint n = 1u; n <= depth; ++n) {
      const uint sh = level - c.level - n;
      const uint child = ((x >> sh) & 1u) | (((y >> sh) & 1u) << 1u);
      const uint stride = n == 1u ? 21u : n == 2u ? 5u : 1u;
      p[n] = p[n - 1u] + 1u + stride * child;
    }
    uint m = 0u;  // the treelet level of the set bit that answers (0: none did)
    for (int n = int(depth); n >= 0; --n) {
      const uint q = p[n];
      const uint word = q < 32u ? w0 : q < 64u ? w1 : w2;
      if (((word >> (q & 31u)) & 1u) == 0u) continue;
      const uint below_mask = (1u << (q & 31u)) - 1u;
      uint before;
      if (q < 32u) before = uint(bitCount(w0 & below_mask));
      else if (q < 64u) before = uint(bitCount(w0)) + uint(bitCount(w1 & below_mask));
      else before = uint(bitCount(w0)) + uint(bitCount(w1)) + uint(bitCount(w2 & below_mask));
      index = c.base + before;
      m = uint(n);
      break;
    }
    // subtrees below treelet levels 0, 1, 2: 85, 21, 5 bits
    while (m < depth && st_treelet_any(w0, w1, w2, p[m] + 1u, p[m] + (m == 0u ? 85u : m == 1u ? 21u : 5u))) ++m;
    shift += level - c.level - m;
  }
  return st_dag_value(base, chunk_words, mult_words, index);
}
float st_dag_depth(uint base, uint level, uint x, uint y, out uint shift) {
  return st_dag_depth_in(st_dag_open(base), level, x, y, shift);
}
float st_dag_depth(uint base, uint level, uint x, uint y) {
  uint shift;
  return st_dag_depth(base, level, x, y, shift);
}

// ---- voxel shadow DAG tiles (voxelized shadows 2014 §4, §6.2; tiles/core/VSDAG.md) ----
// The mirror of vsdag::View::lit, first_shadow_slab and VsdagEvaluator::depth over header
// words 3..6 (xy_bits, z_bits, grid_xy_bits, grid_z_bits) and 10..12 (byte offsets of the
// leaves, grid and nodes). The inner splits are recomputed top down as vsdag::Shape::of
// does: the axis with more splits left splits alone, equal counts split both.
uint st_vsdag_ref_slot(uint mask, uint c) {
  const uint mixed = (mask >> 1u) & ~mask & 0x5555u;
  return uint(bitCount(mixed & ((1u << (2u * c)) - 1u)));
}

bool st_vsdag_lit(uint base, uint x, uint y, uint k) {
  const uint xy_bits = ST_POOL(base + 3u), z_bits = ST_POOL(base + 4u);
  const uint gx = ST_POOL(base + 5u), gz = ST_POOL(base + 6u);
  const uint padded = max(xy_bits, 3u);
  const uint leaves = base + (ST_POOL(base + 10u) >> 2u);
  const uint grid = base + (ST_POOL(base + 11u) >> 2u);
  const uint nodes = base + (ST_POOL(base + 12u) >> 2u);
  const uint xs = padded - gx, zs = z_bits - gz;
  const uint cell = ST_POOL(grid + (((k >> zs) << (2u * gx)) | ((y >> xs) << gx) | (x >> xs)));
  if ((cell >> 30u) != 2u) return (cell >> 30u) == 1u;
  uint w = cell & 0x3FFFFFFFu;
  uint a = xs - 3u, b = zs - 3u;  // splits left below the grid
  while (a > 0u || b > 0u) {
    const bool split_xy = a >= b, split_z = b >= a;
    uint c = 0u;
    if (split_xy) {
      a -= 1u;
      c |= ((x >> (3u + a)) & 1u) | (((y >> (3u + a)) & 1u) << 1u);
    }
    if (split_z) {
      b -= 1u;
      c |= ((k >> (3u + b)) & 1u) << 2u;
    }
    const uint mask = ST_POOL(nodes + w), s = (mask >> (2u * c)) & 3u;
    if (s != 2u) return s == 1u;
    w = ST_POOL(nodes + w + 1u + st_vsdag_ref_slot(mask, c));
  }
  const uint mask = ST_POOL(nodes + w), c = k & 7u, s = (mask >> (2u * c)) & 3u;
  if (s != 2u) return s == 1u;
  const uint leaf = ST_POOL(nodes + w + 1u + st_vsdag_ref_slot(mask, c));
  const uint bit = (y & 7u) * 8u + (x & 7u);
  return ((ST_POOL(leaves + 2u * leaf + (bit >> 5u)) >> (bit & 31u)) & 1u) != 0u;
}

float st_vsdag_depth(uint base, uint level, uint x, uint y) {
  const uint finest = ST_POOL(base + 3u), z_bits = ST_POOL(base + 4u);
  if (level > finest) {
    const uint sh = level - finest;
    x = sh >= 32u ? 0u : x >> sh;
    y = sh >= 32u ? 0u : y >> sh;
    level = finest;
  }
  const uint top = (1u << level) - 1u;
  x = min(x, top) << (finest - level);
  y = min(y, top) << (finest - level);
  // first_shadow_slab: bisection over the column
  const uint slabs = 1u << z_bits;
  uint a = 0u, b = slabs;
  while (a < b) {
    const uint m = a + (b - a) / 2u;
    if (st_vsdag_lit(base, x, y, m)) a = m + 1u;
    else b = m;
  }
  if (a >= slabs) return uintBitsToFloat(kLitDepthBits);
  if (a == 0u) return uintBitsToFloat(0x80000001u);  // nextafter(0, -1): -denorm_min
  // f / 2^z_bits is exact (a power-of-two scale, f < 2^20); its predecessor is one bit below
  precise float q = float(a) * uintBitsToFloat((127u - z_bits) << 23u);
  return uintBitsToFloat(floatBitsToUint(q) - 1u);
}

// ---- plane tiles (tiles/core/PLANES.md, plane_format.hpp, plane_tile.cpp) ----
// Integers only, in 32-bit word pairs: v = a + b x + c y modulo 2^64, then v 2^-60 to the
// nearest binary32 (ties to even) built from its bits, as plane_fixed_to_float does.
uint st_spread16(uint v) {
  v = (v | (v << 8u)) & 0x00FF00FFu;
  v = (v | (v << 4u)) & 0x0F0F0F0Fu;
  v = (v | (v << 2u)) & 0x33333333u;
  return (v | (v << 1u)) & 0x55555555u;
}
// (hi, lo) += (bh, bl) * k for k < 2^16, modulo 2^64.
void st_mad64(inout uint hi, inout uint lo, uint bl, uint bh, uint k) {
  uint mh, ml, carry;
  umulExtended(bl, k, mh, ml);
  lo = uaddCarry(lo, ml, carry);
  hi = hi + bh * k + mh + carry;
}
float st_plane_round(uint hi, uint lo) {
  if ((hi & 0x80000000u) != 0u || (hi | lo) == 0u) return 0.0;
  if (hi >= 0x10000000u) return 1.0;  // v >= 2^60
  const int p = hi != 0u ? 32 + findMSB(hi) : findMSB(lo);
  uint m;
  if (p <= 23) {
    m = lo << uint(23 - p);
  } else {
    const int k = p - 23;  // 1..36 dropped bits
    m = k < 32 ? (lo >> uint(k)) | (k == 0 ? 0u : hi << uint(32 - k)) : hi >> uint(k - 32);
    const int j = k - 1;   // the half bit
    const bool halfbit = ((j < 32 ? lo >> uint(j) : hi >> uint(j - 32)) & 1u) != 0u;
    const bool below = j == 0 ? false
                     : j < 32 ? (lo & ((1u << uint(j)) - 1u)) != 0u
                              : lo != 0u || (j > 32 && (hi & ((1u << uint(j - 32)) - 1u)) != 0u);
    if (halfbit && (below || (m & 1u) != 0u)) m += 1u;
  }
  return uintBitsToFloat((uint(p - 60 + 127) << 23u) + (m - 0x800000u));
}
// Whether plane tile `base` answers (rel, x, y); its depth in `d`. Words: 2 block count B,
// 4 table count T, 5 labelled blocks L, 6 the table (6 words a plane: a, b, c), 6 + 6T the
// blocks (2 words: start, shift | kind << 8 | index << 16), 6 + 6T + 2B the labelled blocks
// (6-word slots: kind 1 palette u16 x 4, 2-bit labels; kind 2, two slots: palette u16 x 8,
// 3 bit planes of 2 words); v = a + b fx + c fy modulo 2^64 in tile coordinates.
bool st_plane_lookup(uint base, uint rel, uint x, uint y, out float d) {
  const uint finest = ((ST_POOL(base + 1u) >> 16u) & 0xFFu) - 1u;
  const uint s = finest - min(rel, finest);
  if (s >= 8u) return false;
  const uint h = s == 0u ? 0u : 1u << (s - 1u);
  const uint fx = (x << s) + h, fy = (y << s) + h;
  const uint key = st_spread16(fx) | (st_spread16(fy) << 1u);
  const uint blocks = base + 6u + 6u * ST_POOL(base + 4u);
  uint a = 0u, b = ST_POOL(base + 2u);  // the last block whose start <= key
  while (a < b) {
    const uint mid = (a + b) >> 1u;
    if (ST_POOL(blocks + 2u * mid) <= key) a = mid + 1u;
    else b = mid;
  }
  if (a == 0u) return false;
  const uint r = blocks + 2u * (a - 1u);
  const uint start = ST_POOL(r), w = ST_POOL(r + 1u), shift = w & 0xFFu;
  if (shift <= s || key - start >= (1u << (2u * shift))) return false;
  uint entry = w >> 16u;
  const uint kind = (w >> 8u) & 0xFFu;
  if (kind != 0u) {  // labelled 8x8 block: the texel's label picks the plane
    const uint lb = blocks + 2u * ST_POOL(base + 2u) + 6u * entry;
    const uint i = ((fy & 7u) << 3u) | (fx & 7u);
    uint label;
    if (kind == 1u) {
      label = (ST_POOL(lb + 2u + (i >> 4u)) >> (2u * (i & 15u))) & 3u;
    } else {  // wide: bit k of the label in bit plane k (words 4 + 2k, 5 + 2k)
      const uint bw = lb + 4u + (i >> 5u), bit = i & 31u;
      label = ((ST_POOL(bw) >> bit) & 1u) | (((ST_POOL(bw + 2u) >> bit) & 1u) << 1u) | (((ST_POOL(bw + 4u) >> bit) & 1u) << 2u);
    }
    entry = (ST_POOL(lb + (label >> 1u)) >> (16u * (label & 1u))) & 0xFFFFu;
  }
  const uint t = base + 6u + 6u * entry;
  uint hi = ST_POOL(t + 1u), lo = ST_POOL(t);
  st_mad64(hi, lo, ST_POOL(t + 2u), ST_POOL(t + 3u), fx);
  st_mad64(hi, lo, ST_POOL(t + 4u), ST_POOL(t + 5u), fy);
  d = st_plane_round(hi, lo);
  return true;
}

// Texel i (8 y + x) of a labelled block's label from its label words: kind 1, words 2..5 of
// its slot (2 bits a texel); kind 2 (wide), words 4..9 (bit plane k in words 2k, 2k + 1).
uint st_plane_label(uint kind, uint l0, uint l1, uint l2, uint l3, uint l4, uint l5, uint i) {
  if (kind == 1u) {
    const uint q = i >> 4u;
    return ((q == 0u ? l0 : q == 1u ? l1 : q == 2u ? l2 : l3) >> (2u * (i & 15u))) & 3u;
  }
  const bool upper = i >= 32u;
  const uint b = i & 31u;
  return (((upper ? l1 : l0) >> b) & 1u) | ((((upper ? l3 : l2) >> b) & 1u) << 1u) |
         ((((upper ? l5 : l4) >> b) & 1u) << 2u);
}

// The depth of texel (x, y) of level `rel` below a tile's root, and in `shift` the square
// of texels that share it (st_mh_depth, st_dag_depth; 0 for voxel and plane tiles: a plane
// block may sit where the inner buffer has a missing child).
float st_tile_depth(uint slot, uint rel, uint x, uint y, out uint shift) {
  uint base = slot * ST_PAGE(kPtSlotWords);
  const uint enc = ST_PAGE(kPtEncoding);
  shift = 0u;
  if (enc == 3u) return st_vsdag_depth(base, rel, x, y);
  bool planes = false;
  if (ST_POOL(base) == 0x4E505453u) {  // "STPN": plane blocks over an inner buffer
    float d;
    if (st_plane_lookup(base, rel, x, y, d)) return d;
    base += 6u + 6u * ST_POOL(base + 4u) + 2u * ST_POOL(base + 2u) + 6u * ST_POOL(base + 5u);
    planes = true;
  }
  // A DAG-MH pack's tile may be an MMH buffer, told by its magic "STMM" (tiles/PACK.md
  // "Mixed tiles"; encoding.cpp open_encoded).
  const bool mmh_tile = enc == 2u && ST_POOL(base) == 0x4D4D5453u;
  uint s;
  const float d = enc == 2u && !mmh_tile ? st_dag_depth(base, rel, x, y, s)
                                         : st_mh_depth(base, rel, x, y, enc == 1u || mmh_tile, s);
  shift = planes ? 0u : min(s, rel);
  return d;
}

// ---- the page-table walk (page_table.hpp walk_page_table; client/remote_map_lookups.cpp enter_tile) ----
// Where a texel's answer lives, and the square (level l, ex, ey) of texels whose walk
// ends the same way (same value, same tile, same absent tile): PCF taps inside it skip
// the walk (the shared walk of MH §3.3, at the page-table level).
struct StWalk {
  uint kind;  // 0 value, 1 tile (decode in `slot`), 2 absent (value = the coarse answer)
  float value;
  uint slot, rel, l, ex, ey;
  uint key, value_bits, kind_word;  // absent: what the feedback records
};

// The page table's header words a walk reads, read once (st_pcf_plane: before its loops).
struct StPt {
  uint map_level, skip_level, slot_words, skip_coarse, skip_entries, skip_slots, child_slots;
};
StPt st_pt() {
  return StPt(ST_PAGE(kPtMapLevel), ST_PAGE(kPtSkipLevel), ST_PAGE(kPtSlotWords), ST_PAGE(kPtSkipCoarse),
              ST_PAGE(kPtSkipEntries), ST_PAGE(kPtSkipSlots), ST_PAGE(kPtChildSlots));
}

StWalk st_walk(StPt pt, uint level, uint x, uint y) {
  StWalk w;
  w.kind = 0u;
  w.slot = kNoSlot;
  w.rel = 0u;
  w.l = level;
  w.ex = x;
  w.ey = y;
  w.key = 0u;
  w.value_bits = kLitDepthBits;
  w.kind_word = 0u;
  const uint map_level = pt.map_level;
  if (level > map_level || (x >> level) != 0u || (y >> level) != 0u) {
    w.value = uintBitsToFloat(kLitDepthBits);
    return w;
  }
  const uint k = pt.skip_level;
  if (level < k) {
    w.value = uintBitsToFloat(ST_PAGE(pt.skip_coarse + st_coarse_index(level) + (y << level) + x));
    return w;
  }
  uint l = k;
  uint ex = x >> (level - k), ey = y >> (level - k);
  uint e = (ey << k) + ex;
  uint value_bits = ST_PAGE(pt.skip_entries + kEntryWords * e);
  uint kind_word = ST_PAGE(pt.skip_entries + kEntryWords * e + 1u);
  uint ptr = ST_PAGE(pt.skip_slots + e);
  uint key = e + 1u;
  for (;;) {
    const uint kind = kind_word & 0xFFu;
    w.l = l;
    w.ex = ex;
    w.ey = ey;
    w.value = uintBitsToFloat(value_bits);
    if (kind == kKindConstant || l == level) return w;
    const uint rel = level - l;
    const uint lx = x - (ex << rel), ly = y - (ey << rel);
    if (ptr == kNoSlot) {
      w.kind = 2u;
      w.key = key;
      w.value_bits = value_bits;
      w.kind_word = kind_word;
      return w;
    }
    if (kind == kKindTile) {
      w.kind = 1u;
      w.slot = ptr;
      w.rel = rel;
      return w;
    }
    // an index tile: a CutGrid of d levels in slot `ptr`
    const uint d = (kind_word >> 8u) & 0xFFu;
    const uint g = ptr * pt.slot_words + kGridHeaderWords;
    if (rel < d) {
      w.l = level;
      w.ex = x;
      w.ey = y;
      w.value = uintBitsToFloat(ST_POOL(g + st_coarse_index(rel) + (ly << rel) + lx));
      return w;
    }
    const uint cx = lx >> (rel - d), cy = ly >> (rel - d);
    const uint c = (cy << d) + cx;
    ex = (ex << d) + cx;
    ey = (ey << d) + cy;
    l += d;
    const uint ent = g + st_coarse_index(d) + kEntryWords * c;
    value_bits = ST_POOL(ent);
    kind_word = ST_POOL(ent + 1u) & 0xFFFFu;
    key = kFbChildKeyBit | (ptr * kChildTableWords + c);
    ptr = ST_PAGE(pt.child_slots + ptr * kChildTableWords + c);
  }
  return w;  // not reached
}
StWalk st_walk(uint level, uint x, uint y) { return st_walk(st_pt(), level, x, y); }

// The map preview's answer (tiles/core/map_preview.hpp MapPreview::coarse_answer) for
// texel (x, y) of `level` whose walk reached an absent tile at level `reached` with the
// entry value `fallback`: the preview's node at level min(level, K + p) when that is
// finer, the deepest stored node on its path (else the skip-grid entry's value).
float st_preview(uint level, uint x, uint y, uint reached, float fallback) {
  const uint pv = ST_PAGE(kPtPreview);
  const uint k = ST_PAGE(kPtSkipLevel);
  const uint p = ST_PAGE(pv + kPvLevels);
  if (p == 0u || level <= k) return fallback;
  uint j = min(level - k, p);
  if (k + j <= reached) return fallback;
  const uint s = level - k;
  const uint ex = x >> s, ey = y >> s;
  const uint o = ST_PAGE(pv + kPvHeaderWords + (ey << k) + ex);
  if (o == kNoSlot) return fallback;
  const uint rec = ST_PAGE(pv + kPvCells) + o * (kPvCellHeaderWords + 2u * ST_PAGE(pv + kPvMaskWords));
  uint lx = (x >> (s - j)) - (ex << j), ly = (y >> (s - j)) - (ey << j);
  for (; j >= 1u; --j) {
    const uint b = ((1u << (2u * j)) - 4u) / 3u + (ly << j) + lx;
    const uint word = ST_PAGE(rec + kPvCellHeaderWords + (b >> 5u));
    if (((word >> (b & 31u)) & 1u) != 0u) {
      uint rank = uint(bitCount(word & ((1u << (b & 31u)) - 1u)));
      for (uint i = 0u; i < (b >> 5u); ++i) rank += uint(bitCount(ST_PAGE(rec + kPvCellHeaderWords + i)));
      return uintBitsToFloat(ST_PAGE(ST_PAGE(pv + kPvValues) + ST_PAGE(rec) + rank));
    }
    lx >>= 1u;
    ly >>= 1u;
  }
  return uintBitsToFloat(ST_PAGE(rec + 1u));
}

bool st_in_walk(StWalk w, uint level, uint x, uint y) {
  return (x >> (level - w.l)) == w.ex && (y >> (level - w.l)) == w.ey;
}

// The answer for texel (x, y) of `level` given a walk that covers it, and in `shift` the
// square of texels that get the same answer (x >> shift, y >> shift equal): a value
// holds for the walk's square, a tile's path for st_tile_depth's, an absent tile's
// preview answer for the texel alone.
float st_answer(StWalk w, uint level, uint x, uint y, inout StProbe probe, out uint shift) {
  shift = 0u;
  if (w.kind == 1u) {
    const uint rel = level - w.l;
    return st_tile_depth(w.slot, rel, x - (w.ex << rel), y - (w.ey << rel), shift);
  }
  if (w.kind == 2u) {
    st_feedback(w.key, w.l, w.ex, w.ey, w.value_bits, w.kind_word, probe);
    return st_preview(level, x, y, w.l, w.value);
  }
  shift = level - w.l;
  return w.value;
}
float st_answer(StWalk w, uint level, uint x, uint y, inout StProbe probe) {
  uint shift;
  return st_answer(w, level, x, y, probe, shift);
}

float st_depth(uint level, uint x, uint y, inout StProbe probe) {
  return st_answer(st_walk(level, x, y), level, x, y, probe);
}

uint st_pcf_tap(uint x, uint i, uint r, uint side) {
  const int t = int(x) - int((r - 1u) / 2u) + int(i);
  return t < 0 ? 0u : uint(t) >= side ? side - 1u : uint(t);
}

// Taps i, i + 1, ... (< r) of an r-wide kernel about x whose texels lie in the aligned
// span of 2^s texels that holds tap i's (taps clamped at the map's edges included): >= 1.
uint st_pcf_run(uint x, uint i, uint r, uint side, uint s) {
  const int t = int(x) - int((r - 1u) / 2u) + int(i);  // tap i before the clamp
  const uint end = ((st_pcf_tap(x, i, r, side) >> s) + 1u) << s;  // the first texel past the span
  return end >= side ? r - i : min(r - i, uint(int(end) - t));
}

// The least depth of a receiver's plane over texel (tx, ty) of a level s levels above the
// finest (tiles/core/receiver_plane.hpp, receiver_plane_depth, the same float operations
// in its order): plane = (corner, gx, gy), f the receiver's finest texel. Zero slopes
// answer the corner itself (the constant receiver of st_pcf).
float st_plane_depth(vec3 plane, uvec2 f, uint s, uint tx, uint ty) {
  if (plane.y == 0.0 && plane.z == 0.0) return plane.x;
  const int span = 1 << s;
  const int ox = int(tx << s) - int(f.x) + (plane.y < 0.0 ? span : 0);
  const int oy = int(ty << s) - int(f.y) + (plane.z < 0.0 ? span : 0);
  precise float px = plane.y * float(ox);
  precise float along_x = plane.x + px;
  precise float py = plane.z * float(oy);
  precise float d = along_x + py;
  return d;
}

// Counts the block of n x m taps from tap (i, j) whose texels answer `value` (st_pcf_plane):
// its taps not in (done0, done1, done2) yet, all at once where the plane's greatest depth over
// the block is lit, none where its least is not, else one by one; marks them done.
void st_pcf_block(uint x, uint y, uint r, uint side, uint i, uint j, uint n, uint m, float value, vec3 plane,
                  uvec2 f, uint up, inout uint lit, inout uint done0, inout uint done1, inout uint done2) {
  const uint x0 = st_pcf_tap(x, i, r, side), x1 = st_pcf_tap(x, i + n - 1u, r, side);
  const uint y0 = st_pcf_tap(y, j, r, side), y1 = st_pcf_tap(y, j + m - 1u, r, side);
  const bool all = st_lit(st_plane_depth(plane, f, up, plane.y < 0.0 ? x0 : x1, plane.z < 0.0 ? y0 : y1), value);
  const bool some = all || st_lit(st_plane_depth(plane, f, up, plane.y < 0.0 ? x1 : x0, plane.z < 0.0 ? y1 : y0), value);
  for (uint jj = j; jj < j + m; ++jj) {
    const uint lo = jj * r + i, hi = lo + n;
    const uint b0 = st_bit_span(lo, hi, 0u) & ~done0, b1 = st_bit_span(lo, hi, 32u) & ~done1,
               b2 = st_bit_span(lo, hi, 64u) & ~done2;
    if (all) {
      lit += uint(bitCount(b0) + bitCount(b1) + bitCount(b2));
    } else if (some) {  // the block straddles the value: its new taps one by one
      const uint yy = st_pcf_tap(y, jj, r, side);
      for (uint ii = i; ii < i + n; ++ii) {
        const uint bit = jj * r + ii;
        const uint word = bit < 32u ? b0 : bit < 64u ? b1 : b2;
        if (((word >> (bit & 31u)) & 1u) != 0u && st_lit(st_plane_depth(plane, f, up, st_pcf_tap(x, ii, r, side), yy), value))
          ++lit;
      }
    }
    done0 |= b0;
    done1 |= b1;
    done2 |= b2;
  }
}

// st_answer for st_pcf_plane's second loop, whose walks are absent tiles and voxel tiles alone
// (the first loop answers values and every other tile): a tile is decoded as a voxel tile
// (st_tile_depth's answer for one: shift 0), so no other decoder is compiled into the loop.
float st_answer_rest(StPt pt, StWalk w, uint level, uint x, uint y, inout StProbe probe, out uint shift) {
  shift = 0u;
  if (w.kind == 1u) {
    const uint rel = level - w.l;
    return st_vsdag_depth(w.slot * pt.slot_words, rel, x - (w.ex << rel), y - (w.ey << rel));
  }
  if (w.kind == 2u) {
    st_feedback(w.key, w.l, w.ex, w.ey, w.value_bits, w.kind_word, probe);
    return st_preview(level, x, y, w.l, w.value);
  }
  shift = level - w.l;
  return w.value;
}

// The first tap (row-major index) of an r x r kernel not in the mask (w0, w1, w2); 96: none.
uint st_pcf_next(uint w0, uint w1, uint w2) {
  const int f0 = findLSB(~w0), f1 = findLSB(~w1), f2 = findLSB(~w2);
  return f0 >= 0 ? uint(f0) : f1 >= 0 ? 32u + uint(f1) : f2 >= 0 ? 64u + uint(f2) : 96u;
}

// r x r PCF (evaluator.hpp: lit taps / (r * r) in float, taps clamped to the map), each tap
// compared with the receiver plane's least depth over its texel (st_plane_depth: `finest`
// the map's finest level, f the receiver's finest texel; zero slopes: one receiver depth,
// Evaluator::pcf; else pcf_plane, tiles/core/receiver_plane.hpp). The
// quotient comes from a table the host filled with the CPU's division, so no GPU
// division (not correctly rounded in Vulkan) enters the answer. Taps are counted in
// blocks (MH §3.3's hierarchical PCF): a tap's answer holds for the square of texels its
// walk and tile path share (st_answer's shift), so every tap of the kernel in that square
// (a block of n x m taps from it, clamped edge taps included) counts with it, and the next
// walk starts at the first tap not counted yet (a mask of counted taps; a block may overlap
// an earlier, smaller one: only its new taps count). A block's plane depths are least and
// greatest at two opposite corner taps (float rounding is monotone): all lit at the
// greatest, or none at the least, counts the block at once; else its new taps one by one.
// A kernel inside one page-table value, leaf or missing child costs one walk. The count is
// the per-tap count, so the answer is the CPU's bit for bit.
// Two loops: the first answers the taps of page-table values and of MH, MMH, DAG-MH and plane
// tiles and leaves the others (absent and voxel tiles) for the second, which answers any tap
// (st_answer). The first walks once a pass and opens the walk's tile once (a DAG-MH tile's
// header, a plane tile's sections), then counts the walk's taps in its inner loop. A plane
// tile's block is searched once per block (its record and labels kept for its next taps),
// and every kernel tap in the block with the same plane as the first tap not counted is
// counted with it, from the plane's words read once; a tap no block answers takes the inner
// buffer's answer for its texel alone (st_tile_depth's shift).
// A device that runs every branch of a loop body under a lane mask (llvmpipe) pays for the
// decoders no tap needs once per loop pass, not once per tap: the first loop's body is small,
// and its inner loop's smaller (no walk, no tile header).
float st_pcf_plane(uint level, uint x, uint y, uint r, vec3 plane, uvec2 f, uint finest, inout StProbe probe) {
  r = clamp(r, 1u, kMaxPcf);
  const StPt pt = st_pt();
  if (level > pt.map_level) return 1.0;
  const uint side = 1u << level, up = finest - level, taps = r * r;
  // taps counted so far: bit j * r + i of (done0, done1, done2); r * r <= 81. Left to the
  // second loop: (later0, later1, later2).
  uint lit = 0u, done0 = 0u, done1 = 0u, done2 = 0u, later0 = 0u, later1 = 0u, later2 = 0u;
  const uint enc = ST_PAGE(kPtEncoding);
  uint k = 0u;
  StWalk w;
  StDagTile t;  // w's tile (its header decoded once per walk)
  bool lean = false, dag = false, mmh = false;  // an MH/MMH/DAG-MH/plane tile; which
  bool planes = false;  // w's tile is a plane tile at pbase
  uint pbase = 0u;
  uint mh_hdr = 0u, mh_root = 0u;  // w's MH or MMH tile: header word 1, the root's value bits
  // w's plane tile (planes): its finest level, block count, records and labelled blocks; and
  // the block record of its last search (bstart, bword; bshift 0: none) with that block's
  // labels (st_plane_label's l0..l5; every word read lies inside the tile, those a kind
  // does not use are ignored).
  uint pfinest = 0u, pcount = 0u, pblocks = 0u, plabels = 0u;
  uint bstart = 0u, bword = 0u, bshift = 0u, blb = 0u, l0 = 0u, l1 = 0u, l2 = 0u, l3 = 0u, l4 = 0u, l5 = 0u;
  while (k < taps) {  // one walk a pass: its tile opened once, its taps in the inner loop
    {
      const uint j = k / r, i = k - j * r;
      w = st_walk(pt, level, st_pcf_tap(x, i, r, side), st_pcf_tap(y, j, r, side));
    }
    lean = false;
    if (w.kind == 1u) {
      pbase = w.slot * pt.slot_words;
      uint base = pbase;
      uvec4 ph, pl;  // a plane tile's header: magic, finest, blocks, -, planes, labelled blocks
      st_pool_run8(base, 6u, ph, pl);
      planes = ph.x == 0x4E505453u;  // "STPN": plane blocks over an inner buffer (st_tile_depth)
      bshift = 0u;
      if (planes) {
        pfinest = ((ph.y >> 16u) & 0xFFu) - 1u;
        pcount = ph.z;
        pblocks = base + 6u + 6u * pl.x;
        plabels = pblocks + 2u * pcount;
        base = plabels + 6u * pl.y;
      }
      const uvec4 head = st_pool_run(base, 2u);  // magic, MH header word 1
      mmh = enc == 1u || (enc == 2u && head.x == 0x4D4D5453u);  // "STMM": a DAG-MH pack's MMH tile
      dag = enc == 2u && !mmh;
      lean = enc != 3u;  // not a voxel tile
      if (dag) t = st_dag_open(base);
      t.base = base;
      mh_hdr = head.y;
      if (lean && !dag) mh_root = st_mh_root(base, mh_hdr);  // an MH or MMH tile
    }
    if (w.kind == 2u || (w.kind == 1u && !lean)) {  // the second loop's: every tap of the kernel in w's square
      const uint j = k / r, i = k - j * r;
      const uint sw = level - w.l, n = st_pcf_run(x, i, r, side, sw), m = st_pcf_run(y, j, r, side, sw);
      for (uint jj = j; jj < j + m; ++jj) {
        const uint lo = jj * r + i, hi = lo + n;
        later0 |= st_bit_span(lo, hi, 0u) & ~done0;
        later1 |= st_bit_span(lo, hi, 32u) & ~done1;
        later2 |= st_bit_span(lo, hi, 64u) & ~done2;
      }
      k = st_pcf_next(done0 | later0, done1 | later1, done2 | later2);
    } else {
      // A plane tile's taps first, in a loop of their own: every tap of the walk that a plane
      // block answers is counted by plane and block (st_plane_lookup's block search, once per
      // plane and block); a tap no block answers is left (pend) to the decode loop below, which
      // answers it from the inner buffer alone (st_tile_depth's shift). So neither loop's body
      // carries the other's reads (a lane-masked device runs a loop body's every read each pass).
      uint pend0 = 0u, pend1 = 0u, pend2 = 0u;
      const bool grouping = w.kind == 1u && planes;
      bool more = grouping;
      while (more) {  // w's plane taps, from tap k
        const uint j = k / r, i = k - j * r;
        const uint tx = st_pcf_tap(x, i, r, side), ty = st_pcf_tap(y, j, r, side);
        const uint rel = level - w.l;
        const uint lx = tx - (w.ex << rel), ly = ty - (w.ey << rel);
        const uint ps = pfinest - min(rel, pfinest);
        const uint h = ps == 0u ? 0u : 1u << (ps - 1u);
        const uint fx = (lx << ps) + h, fy = (ly << ps) + h;
        const uint key = st_spread16(fx) | (st_spread16(fy) << 1u);
        bool in_block = bshift > ps && key - bstart < (1u << (2u * bshift));
        if (!in_block && ps < 8u) {
          uint a = 0u, b = pcount;  // the last block whose start <= key
          while (a < b) {
            const uint mid = (a + b) >> 1u;
            if (ST_POOL(pblocks + 2u * mid) <= key) a = mid + 1u;
            else b = mid;
          }
          if (a != 0u) {
            const uint rec = pblocks + 2u * (a - 1u);
            bstart = ST_POOL(rec);
            bword = ST_POOL(rec + 1u);
            bshift = bword & 0xFFu;
            blb = plabels + 6u * (bword >> 16u);
            const uint bkind = (bword >> 8u) & 0xFFu;  // kind 0: six words of the tile's records and past, unused
            const uint lw = bkind == 0u ? rec : blb + (bkind == 2u ? 4u : 2u);
            uvec4 la, lb;
            st_pool_run8(lw, 6u, la, lb);
            l0 = la.x;
            l1 = la.y;
            l2 = la.z;
            l3 = la.w;
            l4 = lb.x;
            l5 = lb.y;
            in_block = bshift > ps && key - bstart < (1u << (2u * bshift));
          }
        }
        if (in_block) {
          // Tap k's plane (its label's palette entry in a labelled block), then every tap of the
          // kernel not counted yet in the block (an aligned square of 2^(bshift - ps) texels
          // holding tap k's; rows before j are counted) whose texel has that plane: its
          // depth as st_plane_lookup's, each compared alone (st_pcf_block's 1 x 1 block).
          const uint kind = (bword >> 8u) & 0xFFu;
          const uint label = st_plane_label(kind, l0, l1, l2, l3, l4, l5, ((fy & 7u) << 3u) | (fx & 7u));
          const uint entry =
              kind == 0u ? bword >> 16u : (ST_POOL(blb + (label >> 1u)) >> (16u * (label & 1u))) & 0xFFFFu;
          const uint pt = pbase + 6u + 6u * entry;
          uvec4 pa, pc;  // the plane's a, b (64-bit, low word first); then c
          st_pool_run8(pt, 6u, pa, pc);
          const uint a_lo = pa.x, a_hi = pa.y, b_lo = pa.z, b_hi = pa.w, c_lo = pc.x, c_hi = pc.y;
          const uint sb = bshift - ps, ox = w.ex << rel, oy = w.ey << rel;
          const uint low = (tx >> sb) << sb;  // the block's first texel of `level` along x
          const int from = int(low) - int(x) + int((r - 1u) / 2u);
          const uint i0 = low == 0u ? 0u : uint(max(from, 0));  // its first tap column
          const uint n = st_pcf_run(x, i0, r, side, sb), m = st_pcf_run(y, j, r, side, sb);
          for (uint jj = j; jj < j + m; ++jj) {
            const uint yy = st_pcf_tap(y, jj, r, side);
            const uint fyy = ((yy - oy) << ps) + h;
            for (uint ii = i0; ii < i0 + n; ++ii) {
              const uint bit = jj * r + ii;
              const uint word = bit < 32u ? done0 : bit < 64u ? done1 : done2;
              const uint xx = st_pcf_tap(x, ii, r, side);
              const uint fxx = ((xx - ox) << ps) + h;
              const uint texel = ((fyy & 7u) << 3u) | (fxx & 7u);
              const uint other = kind == 0u ? label : st_plane_label(kind, l0, l1, l2, l3, l4, l5, texel);
              if (((word >> (bit & 31u)) & 1u) != 0u || other != label) continue;
              uint hi = a_hi, lo = a_lo;
              st_mad64(hi, lo, b_lo, b_hi, fxx);
              st_mad64(hi, lo, c_lo, c_hi, fyy);
              if (st_lit(st_plane_depth(plane, f, up, xx, yy), st_plane_round(hi, lo))) ++lit;
              const uint one = 1u << (bit & 31u);
              if (bit < 32u) done0 |= one;
              else if (bit < 64u) done1 |= one;
              else done2 |= one;
            }
          }
        } else {  // no block: the inner buffer's answer, in the decode loop
          const uint one = 1u << (k & 31u);
          if (k < 32u) pend0 |= one;
          else if (k < 64u) pend1 |= one;
          else pend2 |= one;
        }
        k = st_pcf_next(done0 | later0 | pend0, done1 | later1 | pend1, done2 | later2 | pend2);
        more = k < taps && st_in_walk(w, level, st_pcf_tap(x, k % r, r, side), st_pcf_tap(y, k / r, r, side));
      }
      if (grouping) k = st_pcf_next(done0 | later0, done1 | later1, done2 | later2);  // the first tap pending, if any
      more = k < taps && st_in_walk(w, level, st_pcf_tap(x, k % r, r, side), st_pcf_tap(y, k / r, r, side));
      while (more) {  // w's taps not counted, from tap k: a value, or decoded (DAG-MH, MH, MMH)
        const uint j = k / r, i = k - j * r;
        const uint tx = st_pcf_tap(x, i, r, side), ty = st_pcf_tap(y, j, r, side);
        uint s = level - w.l;
        float value = w.value;
        if (w.kind == 1u) {
          const uint rel = level - w.l;
          const uint lx = tx - (w.ex << rel), ly = ty - (w.ey << rel);
          value = dag ? st_dag_depth_in(t, rel, lx, ly, s) : st_mh_depth_at(t.base, mh_hdr, mh_root, rel, lx, ly, mmh, s);
          s = planes ? 0u : min(s, rel);  // st_tile_depth's shift
        }
        st_pcf_block(x, y, r, side, i, j, st_pcf_run(x, i, r, side, s), st_pcf_run(y, j, r, side, s), value, plane, f, up,
                     lit, done0, done1, done2);
        k = st_pcf_next(done0 | later0, done1 | later1, done2 | later2);
        more = k < taps && st_in_walk(w, level, st_pcf_tap(x, k % r, r, side), st_pcf_tap(y, k / r, r, side));
      }
    }
  }
  // The rest: any tap (st_answer). An absent tile's taps go one by one: each is counted in
  // the feedback.
  k = st_pcf_next(~later0 | done0, ~later1 | done1, ~later2 | done2);
  if (k < taps) w = st_walk(pt, level, st_pcf_tap(x, k % r, r, side), st_pcf_tap(y, k / r, r, side));
  while (k < taps) {
    const uint j = k / r, i = k - j * r;
    const uint tx = st_pcf_tap(x, i, r, side), ty = st_pcf_tap(y, j, r, side);
    if (!st_in_walk(w, level, tx, ty)) w = st_walk(pt, level, tx, ty);  // else: the same walk
    uint s;
    const float value = st_answer_rest(pt, w, level, tx, ty, probe, s);
    const uint n = w.kind == 2u ? 1u : st_pcf_run(x, i, r, side, s);
    const uint m = w.kind == 2u ? 1u : st_pcf_run(y, j, r, side, s);
    st_pcf_block(x, y, r, side, i, j, n, m, value, plane, f, up, lit, done0, done1, done2);
    k = st_pcf_next(~later0 | done0, ~later1 | done1, ~later2 | done2);
  }
  return uintBitsToFloat(ST_PAGE(ST_PAGE(kPtPcfTable) + (r - 1u) * kPcfTableStride + lit));
}
float st_pcf(uint level, uint x, uint y, uint r, float receiver, inout StProbe probe) {
  return st_pcf_plane(level, x, y, r, vec3(receiver, 0.0, 0.0), uvec2(0u), level, probe);
}

// Hierarchical filtering, the one place the GPU makes it: the mirror of filter_levels and
// filter_blend (tiles/core/filter_level.hpp), which Evaluator::pcf_footprint uses. The
// footprint's exponent picks the two nearest levels by integer operations; its mantissa,
// as a float in [1, 2) minus 1 (exact), is the weight of the coarser one; the blend is
// a + t * (c - a), one rounding per operation (precise: never fused).
struct StFilter {
  uint fine, coarse;
  float t;
};
StFilter st_filter_levels(float footprint, uint finest) {
  StFilter f = StFilter(finest, finest, 0.0);
  if (!(footprint > 1.0) || finest == 0u) return f;  // NaN, one texel or less
  const uint b = floatBitsToUint(footprint);
  const uint e = (b >> 23u) - 127u;  // footprint > 1: sign 0, e >= 0 (+inf: 128)
  if (e >= finest) return StFilter(0u, 0u, 0.0);
  precise float t = uintBitsToFloat((b & 0x7FFFFFu) | 0x3F800000u) - 1.0;
  return StFilter(finest - e, finest - e - 1u, t);
}

// (x, y): texel of the finest level. The two levels from the footprint, r x r PCF at each
// (the texel at a coarser level is the finest one shifted) against the receiver plane
// (corner, gx, gy) of st_pcf_plane, blended; t == 0: the fine level alone, as on the CPU
// (pcf_footprint_plane, tiles/core/receiver_plane.hpp).
float st_lookup_plane(uint x, uint y, vec3 plane, float footprint, uint r, inout StProbe probe) {
  const uint finest = ST_PAGE(kPtMapLevel);
  const StFilter f = st_filter_levels(footprint, finest);
  // One call site of st_pcf_plane for both levels: a shader compiler inlines the walk and the
  // decoders once (half the pipeline compile time of two sites).
  float a = 0.0, c = 0.0;
  for (uint k = 0u; k < (f.t == 0.0 ? 1u : 2u); ++k) {
    const uint l = k == 0u ? f.fine : f.coarse;
    const float v = st_pcf_plane(l, x >> (finest - l), y >> (finest - l), r, plane, uvec2(x, y), finest, probe);
    if (k == 0u) a = v;
    else c = v;
  }
  if (f.t == 0.0) return a;
  precise float step = c - a;
  precise float scaled = f.t * step;
  precise float blended = a + scaled;
  return blended;
}
// The same with one receiver depth for every tap (Evaluator::pcf_footprint).
float st_lookup(uint x, uint y, float receiver, float footprint, uint r, inout StProbe probe) {
  return st_lookup_plane(x, y, vec3(receiver, 0.0, 0.0), footprint, r, probe);
}

#endif
