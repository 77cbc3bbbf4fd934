#include "tiles/core/stack_map.hpp"

#include <algorithm>
#include <bit>
#include <cmath>

#include "tiles/core/evaluator.hpp"
#include "tiles/core/filter_level.hpp"
#include "tiles/core/interval.hpp"
#include "tiles/core/mh_quadtree_format.hpp"

namespace st {

StackMap::StackMap(const StackGrid& grid, TileSource tiles) : grid_(grid), tiles_(std::move(tiles)) {
  if (!tiles_) tiles_ = [](const uint64_t*, uint32_t n, StackTileRef* out) { std::fill(out, out + n, StackTileRef()); };
  lights_.reserve(grid.slices);
  for (uint32_t w = 0; w < grid.slices; ++w) lights_.push_back(grid.light(w));
  texels_ = SampleTexels(lights_, grid_.geo.n);
}

uint64_t StackMap::cell_of(uint64_t x, uint64_t y, uint32_t w) const {
  uint32_t l;
  return grid_.cell_at(grid_.geo.depth(), grid_.geo.n, x, y, w, l);
}

float StackMap::depth(uint64_t x, uint64_t y, uint32_t w, uint32_t level, bool* exact) const {
  const moct::Geometry& g = grid_.geo;
  if (level > g.n || w >= grid_.slices || (x >> level) || (y >> level)) return kLitDepth;
  const uint32_t K = grid_.skip_level;
  const uint32_t T = g.level_of_xy(level);  // octree level with 2^level texels a side
  if (T < K) {
    const uint32_t a = g.xy_bits(T), b = g.w_bits(T);
    return grid_.coarse[T][grid_.index(T, x >> (level - a), y >> (level - a), uint64_t(w) >> (g.k - b))];
  }
  uint32_t l;  // the cell's level: K, deeper in a split cell, never past T
  const uint64_t cell = grid_.cell_at(T, level, x, y, w, l);
  const StackEntry& e = grid_.entries[cell];
  if (e.kind != 1 || T == l) return e.value;  // a split cell here is at level T
  const uint32_t a = g.xy_bits(l), b = g.w_bits(l);
  const uint64_t cx = x >> (level - a), cy = y >> (level - a), cw = uint64_t(w) >> (g.k - b);
  StackTileRef t;
  tiles_(&cell, 1, &t);
  if (!t) {
    if (exact) *exact = false;
    return e.value;
  }
  const uint32_t rel = level - a;  // the tile's own x, y level
  return t.depth(x - (cx << rel), y - (cy << rel), uint32_t(w - (cw << (g.k - b))), rel);
}

void StackMap::texel(const Vec3d& p, uint32_t w, uint64_t& x, uint64_t& y, float& d) const {
  const LightPoint lp = lights_[w].to_light(p);
  const auto t = LightSpace::texel_of(grid_.geo.n, lp.u, lp.v);
  x = t[0];
  y = t[1];
  d = float(lp.d);
}

StackMap::CellTexel StackMap::cell_texel(uint64_t x, uint64_t y, uint32_t w) const {
  const moct::Geometry& g = grid_.geo;
  if ((x >> g.n) || (y >> g.n)) return {kLitDepth, false, 0, 0, 0, 0};
  uint32_t l;  // K, or deeper in a split cell
  const uint64_t cell = grid_.cell_at(g.depth(), g.n, x, y, w, l);
  const StackEntry& e = grid_.entries[cell];
  const uint32_t sx = g.n - g.xy_bits(l), sw = g.k - g.w_bits(l);
  const uint64_t xy_mask = (uint64_t(1) << sx) - 1;
  return {e.value, e.kind == 1 && g.depth() != l, cell, x & xy_mask, y & xy_mask, w & ((uint32_t(1) << sw) - 1)};
}

bool StackMap::lit(const Vec3d& p, uint32_t w, bool* exact) const {
  if (w >= grid_.slices) return true;
  uint64_t x, y;
  float d;
  texel(p, w, x, y, d);
  return d <= depth(x, y, w, grid_.geo.n, exact);
}

float StackMap::visibility(const Vec3d& p, double time, bool* exact) const {
  const uint32_t n = grid_.slices;
  const double s = std::clamp(std::isnan(time) ? 0.0 : time, 0.0, 1.0) * double(n - 1);
  const double near = std::nearbyint(s);
  if (std::fabs(s - near) <= 1e-9) return lit(p, uint32_t(near), exact) ? 1.0f : 0.0f;
  const uint32_t a = uint32_t(std::floor(s));
  const float f = float(s - double(a));
  // lit(p, a) and lit(p, a + 1), bit for bit, with what the two share done once: both
  // texels in one run of the batched transforms (lit()'s transform, sample_texels.hpp)
  // and both samples settled together by lit_samples (one tile fetch when both lie in one
  // cell, where an octree walk to slice a + 1 resumes from slice a's; different cells'
  // walks in lockstep).
  SampleTexels::Run run;
  texels_.run(p, a, 2, run);
  const uint64_t lit = lit_samples(&run, a, 2, exact);
  const float la = float(lit & 1), lb = float((lit >> 1) & 1);
  return la + f * (lb - la);
}

float StackMap::soft_visibility(const Vec3d& p, bool* exact) const {
  // depth(x, y, w, n) per sample, the texels a run of samples at a time (SampleTexels:
  // lit()'s transform bit for bit), up to kGather samples settled together by lit_samples.
  // The lit count is a sum of per-sample tests, so the order is free.
  SampleTexels::Run runs[kGather / SampleTexels::kRun];
  uint32_t lit = 0;
  for (uint32_t w0 = 0; w0 < grid_.slices; w0 += kGather) {
    const uint32_t m = std::min(kGather, grid_.slices - w0);
    for (uint32_t r = 0; r * SampleTexels::kRun < m; ++r)
      texels_.run(p, w0 + r * SampleTexels::kRun, std::min(SampleTexels::kRun, m - r * SampleTexels::kRun), runs[r]);
    lit += uint32_t(std::popcount(lit_samples(runs, w0, m, exact)));
  }
  return float(lit) / float(grid_.slices);
}

namespace {

// Room for N objects left unset (no zeroing of a lookup's arrays, a few KiB per call): a
// slot is assigned before it is read.
template <class T, size_t N>
union Uninitialized {
  Uninitialized() {}
  T v[N];
};

// The cache lines of an octree's reader object that a walk reads (MhOctree::kWalkBytes).
void stack_map_prefetch_walk(const MhOctree* p) {
  const char* b = reinterpret_cast<const char*>(p);
  for (size_t o = 0; o < MhOctree::kWalkBytes; o += 64) __builtin_prefetch(b + o);
}

// An MMH slice's walk (SliceTiles::RecordKind::mmh) in resumable steps: the evaluator's
// depth(level, x, y) (mh_quadtree_reader.cpp, TreeEvaluator<relative>: root, then
// descend to `level`, a leaf or a missing child, summing the relative values with
// mmh_add) with each child's value read one step later, once the line it lies on (the
// child's, prefetched by the step that went there) has arrived. Same words, same adds in
// the same order: the same float bit for bit.
struct MmhWalk {
  const uint8_t* tree;
  uint64_t pos, vp;     // the current node's word; the value word still to apply (pending)
  float value;          // the decoded value of the last valued node applied
  uint32_t code, level, until;
  uint32_t pending;     // 0 none, 1 relative (mmh_add), 2 absolute
  uint32_t word(uint64_t w) const { return st::load_le<uint32_t>(tree + 4 * w); }
  void begin(const SliceTiles::Record& r) {
    tree = r.base, pos = 0, vp = r.mmh_root_leaf ? 0 : 1, value = 0;
    code = r.mmh_root_leaf ? mhq::kCodeLeaf : mhq::kCodeInner, level = 0, until = r.xy_level, pending = 2;
  }
  // One step towards (x, y) of `until`; false once the walk has its answer (`value`).
  bool step(uint64_t x, uint64_t y) {
    if (pending) {
      const float s = mhq::bits_float(word(vp));
      value = pending == 2 ? s : mhq::mmh_add(value, s);
      pending = 0;
    }
    if (level >= until || code == mhq::kCodeLeaf) return false;
    const uint32_t bit = until - (level + 1);
    const uint32_t slot = uint32_t((x >> bit) & 1u) | uint32_t(((y >> bit) & 1u) << 1);
    const uint32_t w = word(pos);
    const uint32_t mask = mhq::word_mask(w), cc = mhq::child_code(mask, slot);
    if (!cc) return false;
    const uint64_t at = mhq::block_start(pos, mhq::word_shift(w), mhq::word_offset(w)) + mhq::child_skip(mask, slot);
    __builtin_prefetch(tree + 4 * at);
    if (cc != mhq::kCodeEmpty) {
      vp = cc == mhq::kCodeLeaf ? at : at + 1;
      pending = (mhq::word_abs_flags(w) >> slot & 1u) ? 2 : 1;
      __builtin_prefetch(tree + 4 * vp);  // an inner node's value may start the next line
    }
    pos = at, code = cc, ++level;
    return true;
  }
};

}  // namespace

[[gnu::always_inline]] inline uint64_t StackMap::lit_samples_body(const SampleTexels::Run* runs, uint32_t w0,
                                                                 uint32_t m, bool* exact) const {
  // Every sample of the run settled in phases, each phase over all samples before the
  // next, so that the loads of different samples are in flight together rather than one
  // sample's dependent chain after another's (a day's sun moves a raised receiver's texel
  // across cells from one sample to the next: 2CylinderEngine.glb at 1024^2 x 64 keeps
  // 1.7 samples a cell, so nearly every sample reads a cold tile):
  //   1. each sample's cell and entry (outside the slice, a constant cell: the value); a
  //      sample in the previous sample's cell takes it without the grid's descent;
  //   2. the tiles of the distinct cells, in one tiles_ call; each octree's walk fields
  //      (MhOctree::kWalkBytes) and root word prefetched (the ref carries the root:
  //      StackTileRef::root);
  //   3. per-slice samples: their slice's record (SliceTiles::Record, reached from the
  //      ref's records without the reader object, prefetched); octree samples: a lane
  //      each, after the cell's previous octree sample;
  //   4. per-slice samples: the bounds (d <= lo lit, d > hi shadowed exactly as the walk
  //      would say), a constant's value, a DAG-MH walk (skip entry prefetched, then read:
  //      its start, after the next step) or an MMH walk (its root word prefetched),
  //      another 2D tile (its evaluator prefetched; its depth() one per round of step 5);
  //      octree lanes: each forks from the walk of an earlier sample of its cell at the
  //      deepest level their paths share (MhOctree::shared_levels: a cell's samples read
  //      only the nodes where their paths part, as depth_along's walks do), ordered by
  //      that level;
  //   5. rounds of one step of every DAG-MH walk (View::descend's own step), every MMH
  //      walk (MmhWalk) and every octree lane (round r: the lanes forking at level r
  //      join, every live lane steps from level r), each prefetching the node it goes to,
  //      and in the same rounds, a stage a round, each ended DAG-MH walk's finish
  //      (treelet), its value's chunk, the chunk's multiplier bits, and the value.
  // Each answer is the sample's own depth(x, y, w, n), bit for bit (tested).
  constexpr uint32_t G = kGather, R = SampleTexels::kRun;
  CellTexel c[G];
  float d[G];
  {
    // cell_texel per sample, where a sample whose texel agrees with the last in-range
    // sample's above that sample's cell level (x, y above bit sx, w above bit sw) takes
    // its cell and entry without the grid's descent: the descent reads only those bits, so
    // it would end in the same cell (a day's sun keeps runs of samples in one cell).
    const moct::Geometry& g = grid_.geo;
    bool prev = false;
    uint32_t sx = 0, sw = 0, pw = 0, w_mask = 0;
    uint64_t px = 0, py = 0, xy_mask = 0;
    for (uint32_t i = 0; i < m; ++i) {
      const SampleTexels::Run& run = runs[i / R];
      const uint64_t x = run.x[i % R], y = run.y[i % R];
      const uint32_t w = w0 + i;
      d[i] = run.d[i % R];
      if ((x >> g.n) || (y >> g.n)) {
        c[i] = {kLitDepth, false, 0, 0, 0, 0};
        continue;
      }
      if (prev && !(((x ^ px) | (y ^ py)) >> sx) && !((w ^ pw) >> sw)) {
        const CellTexel& p = c[pw - w0];  // the last in-range sample's
        c[i] = {p.value, p.tiled, p.cell, x & xy_mask, y & xy_mask, w & w_mask};
      } else {
        uint32_t l;  // K, or deeper in a split cell
        const uint64_t cell = grid_.cell_at(g.depth(), g.n, x, y, w, l);
        const StackEntry& e = grid_.entries[cell];
        sx = g.n - g.xy_bits(l), sw = g.k - g.w_bits(l);
        xy_mask = (uint64_t(1) << sx) - 1, w_mask = (uint32_t(1) << sw) - 1;
        c[i] = {e.value, e.kind == 1 && g.depth() != l, cell, x & xy_mask, y & xy_mask, w & w_mask};
      }
      prev = true, px = x, py = y, pw = w;
    }
  }
  // The tiles of the distinct cells in a row, fetched in one call (got[of[i]]: sample i's).
  Uninitialized<StackTileRef, G> got;
  uint8_t of[G];
  {
    uint64_t cells[G];
    uint32_t nu = 0;
    for (uint32_t i = 0; i < m; ++i) {
      if (!c[i].tiled) continue;
      if (nu == 0 || c[i].cell != cells[nu - 1]) cells[nu++] = c[i].cell;
      of[i] = uint8_t(nu - 1);
    }
    if (nu) tiles_(cells, nu, got.v);
    for (uint32_t u = 0; u < nu; ++u)
      if (got.v[u].octree) {
        stack_map_prefetch_walk(got.v[u].octree);
        __builtin_prefetch(got.v[u].root);
      }
  }
  uint64_t lit = 0;
  auto set = [&](uint32_t i, bool v) { lit |= uint64_t(v) << i; };
  // Octree samples: one lane each, in sample order, with the lane of the cell's previous
  // octree sample (`back`) and the deepest level its path shares with that one's (`fork`).
  constexpr uint8_t kNone = 0xFF;
  const MhOctree* oct_tree[G];
  uint64_t oct_cell[G];
  uint8_t oct_sample[G], oct_back[G], oct_fork[G], oct_last[G];
  uint32_t no_lanes = 0, ncells = 0, last_cell = 0;
  const SliceTiles::Record* rec[G];
  uint8_t rec_sample[G];
  uint32_t nr = 0;
  for (uint32_t i = 0; i < m; ++i) {
    if (!c[i].tiled) {
      set(i, d[i] <= c[i].value);
    } else if (got.v[of[i]].slices) {
      const SliceTiles::Record* r = static_cast<const SliceTiles::Record*>(got.v[of[i]].root) + c[i].lw;
      __builtin_prefetch(r);  // one line (SliceTiles::Record)
      rec[nr] = r, rec_sample[nr++] = uint8_t(i);
    } else if (got.v[of[i]].octree) {
      uint32_t j = last_cell;  // the cell's index among this call's octree cells
      if (j >= ncells || oct_cell[j] != c[i].cell) {
        j = 0;
        while (j < ncells && oct_cell[j] != c[i].cell) ++j;
        if (j == ncells) oct_cell[ncells++] = c[i].cell, oct_last[j] = kNone;
      }
      last_cell = j;
      const uint32_t q = no_lanes++;
      oct_tree[q] = got.v[of[i]].octree, oct_sample[q] = uint8_t(i), oct_back[q] = oct_last[j];
      oct_last[j] = uint8_t(q);
    } else {
      if (exact) *exact = false;
      set(i, d[i] <= c[i].value);
    }
  }
  // DAG-MH and MMH walks of per-slice samples.
  // Kind view's walks: their records; each step rebuilds the view from its record's line
  // (SliceTiles::Record::dagmh, the fields it reads only) rather than keeping 64 views.
  const SliceTiles::Record* walk_rec[G];
  auto view = [&](uint32_t k) { return walk_rec[k]->dagmh(); };
  const SliceTiles::Record* other[G];
  uint8_t other_sample[G];
  uint32_t no = 0;
  dagmh::Cursor cur[G];
  uint32_t level[G];
  uint8_t walk_sample[G], active[G];
  uint32_t nw = 0;
  MmhWalk mw[G];
  uint8_t mmh_sample[G];
  uint32_t nm = 0;
  for (uint32_t k = 0; k < nr; ++k) {
    const SliceTiles::Record& r = *rec[k];
    const uint32_t i = rec_sample[k];
    if (d[i] <= r.lo) {
      set(i, true);
    } else if (!(d[i] > r.hi)) {  // a constant slice never gets here with a number d
      if (r.kind == SliceTiles::RecordKind::view) {
        // The start is read in the next loop, once every walk's skip entry is on its way.
        walk_rec[nw] = &r, level[nw] = r.xy_level, walk_sample[nw] = uint8_t(i);
        if (r.skip_level > 0 && r.xy_level >= r.skip_level)
          __builtin_prefetch(r.dagmh().skip_entry_at(r.xy_level, c[i].lx, c[i].ly));
        ++nw;
      } else if (r.kind == SliceTiles::RecordKind::mmh) {
        mw[nm].begin(r);
        __builtin_prefetch(r.base);  // the root's word and value
        mmh_sample[nm++] = uint8_t(i);
      } else if (r.kind == SliceTiles::RecordKind::evaluator) {
        // Answered one per round of the walks below, the evaluator's object on its way.
        __builtin_prefetch(r.eval);
        other[no] = &r, other_sample[no++] = uint8_t(i);
      } else {
        set(i, d[i] <= r.lo);
      }
    }
  }
  // Octree lanes: each walks from the node at its fork level, copied from the lane of the
  // cell's nearest earlier sample whose own walk passes there (a lane back along the cell
  // whose fork is no deeper: the paths agree down to the lesser fork). Level by level, so
  // that every lane's step of one level is in flight together (a chain of the cell's
  // samples walked one after another would be one dependent miss after another); the
  // nodes read are those of depth_along's walks (a walk that ended above a lane's fork
  // ends that lane where it ended: the same node, the same value).
  Uninitialized<MhOctree::Walk, G> lanes;  // set when a lane joins
  MhOctree::Walk* const ow = lanes.v;
  uint8_t oct_from[G], order[G], oct_live[G];
  uint32_t n_order = 0;
  {  // (here, between the records' reads and the skip entries', while those are in flight,
     // and once the octrees' objects have had the records' time to arrive)
    uint8_t count[moct::kMaxLevels + 1] = {};
    for (uint32_t q = 0; q < no_lanes; ++q) {
      uint32_t b = oct_back[q];
      oct_fork[q] = 0;
      if (b != kNone) {
        const uint32_t i = oct_sample[q], e = oct_sample[b];
        oct_fork[q] = uint8_t(oct_tree[q]->shared_levels(c[i].lx, c[i].ly, c[i].lw, c[e].lx, c[e].ly, c[e].lw));
      }
      while (b != kNone && oct_fork[b] > oct_fork[q]) b = oct_back[b];
      oct_from[q] = uint8_t(b);
      ++count[oct_fork[q]];
    }
    uint8_t at[moct::kMaxLevels + 1];
    for (uint32_t l = 0, sum = 0; l <= moct::kMaxLevels; ++l) at[l] = uint8_t(sum), sum += count[l];
    for (uint32_t q = 0; q < no_lanes; ++q) order[at[oct_fork[q]]++] = uint8_t(q);  // by fork, stable
    n_order = no_lanes;
  }
  auto descending = [&](uint32_t k) {
    return (cur[k].ref & dagmh::kRefTagMask) == dagmh::kRefInner && cur[k].level < level[k];
  };
  // DAG-MH walks past their descent go through three stages, one a round, beside the other
  // walks' rounds (a walk that ends early has its value's chain in flight while the
  // octree lanes still step): 1. finish (the treelet, prefetched when the descent ended)
  // and the value's chunk prefetched; 2. the chunk's multiplier bits prefetched; 3. the
  // value.
  uint8_t ending[G], stage[G];
  uint32_t index[G];
  uint32_t na = 0, ne = 0;
  auto end_descent = [&](uint32_t k) {
    if ((cur[k].ref & dagmh::kRefTagMask) == dagmh::kRefTreelet)
      __builtin_prefetch(view(k).treelet_at(cur[k].ref & dagmh::kRefIndexMask));
    stage[k] = 1, ending[ne++] = uint8_t(k);
  };
  for (uint32_t k = 0; k < nw; ++k) {  // the starts, each walk's first node on its way
    const uint32_t i = walk_sample[k];
    cur[k] = view(k).start(level[k], level[k], c[i].lx, c[i].ly);
    if (descending(k)) {
      __builtin_prefetch(view(k).node_at(cur[k].ref & dagmh::kRefIndexMask));
      active[na++] = uint8_t(k);
    } else {
      end_descent(k);
    }
  }
  uint8_t mmh_live[G];
  for (uint32_t k = 0; k < nm; ++k) mmh_live[k] = uint8_t(k);
  uint32_t live = 0, nml = nm, next_other = 0, next_fork = 0, round = 0;
  auto answer_other = [&](uint32_t k) {
    const SliceTiles::Record& r = *other[k];
    const uint32_t i = other_sample[k];
    set(i, d[i] <= r.eval->depth(r.xy_level, c[i].lx, c[i].ly));
  };
  while (na || ne || live || nml || next_fork < n_order) {
    if (next_other < no) answer_other(next_other++);
    // The octree lanes forking at this level join (every live lane stands at it).
    for (; next_fork < n_order && oct_fork[order[next_fork]] == round; ++next_fork) {
      const uint32_t q = order[next_fork];
      // A copy of a walk that has ended (above this level) ends again at its first step.
      ow[q] = oct_from[q] == kNone ? oct_tree[q]->along_root() : ow[oct_from[q]];
      oct_live[live++] = uint8_t(q);
    }
    uint32_t kept = 0;
    for (uint32_t a = 0; a < nml; ++a) {  // one step of every MMH walk
      const uint32_t k = mmh_live[a];
      const uint32_t i = mmh_sample[k];
      if (mw[k].step(c[i].lx, c[i].ly)) {
        mmh_live[kept++] = uint8_t(k);
      } else {
        set(i, d[i] <= mw[k].value);
      }
    }
    nml = kept;
    kept = 0;
    for (uint32_t a = 0; a < ne; ++a) {  // one stage of every DAG-MH walk past its descent
      const uint32_t k = ending[a];
      const uint32_t i = walk_sample[k];
      if (stage[k] == 1) {
        index[k] = view(k).finish(cur[k], level[k], c[i].lx, c[i].ly);
        __builtin_prefetch(view(k).chunk_at(index[k]));
      } else if (stage[k] == 2) {
        if (const uint8_t* bits = view(k).value_bits_at(index[k])) __builtin_prefetch(bits);
      } else {
        set(i, d[i] <= view(k).value(index[k]));
        continue;
      }
      ++stage[k], ending[kept++] = uint8_t(k);
    }
    ne = kept;
    kept = 0;
    for (uint32_t a = 0; a < na; ++a) {  // one level of every DAG-MH walk that still descends
      const uint32_t k = active[a];
      const uint32_t i = walk_sample[k];
      cur[k] = view(k).descend(cur[k], cur[k].level + 1, level[k], c[i].lx, c[i].ly);
      if (descending(k)) {
        __builtin_prefetch(view(k).node_at(cur[k].ref & dagmh::kRefIndexMask));
        active[kept++] = uint8_t(k);
      } else {
        end_descent(k);
      }
    }
    na = kept;
    kept = 0;
    for (uint32_t a = 0; a < live; ++a) {  // one step of every octree lane
      const uint32_t q = oct_live[a];
      const MhOctree& tree = *oct_tree[q];
      const uint32_t i = oct_sample[q];
      if (tree.along_step_to(ow[q], c[i].lx, c[i].ly, c[i].lw)) {
        __builtin_prefetch(tree.along_next(ow[q]));
        oct_live[kept++] = uint8_t(q);
      } else {
        set(i, d[i] <= tree.along_value(ow[q]));
      }
    }
    live = kept;
    ++round;
  }
  while (next_other < no) answer_other(next_other++);
  return lit;
}

// x86-64 without a POPCNT target (the baseline this project builds for): lit_samples runs
// a clone of its body compiled for POPCNT where the CPU has it, chosen at run time. The
// body's bit counts (st::bit_count's SWAR form, which the octree, treelet and value ranks
// use) become one instruction there: GCC recognises the form in a function whose target
// has POPCNT. Same integer results, so the same answers bit for bit; any other CPU or
// target runs the plain body.
// (ST_STACK_MAP_POPCNT_CLONE: stack_map.hpp, where the clone is declared on those builds only.)
#ifdef ST_STACK_MAP_POPCNT_CLONE
__attribute__((target("popcnt"))) uint64_t StackMap::lit_samples_popcnt(const SampleTexels::Run* runs, uint32_t w0,
                                                                        uint32_t m, bool* exact) const {
  return lit_samples_body(runs, w0, m, exact);
}
#endif

uint64_t StackMap::lit_samples(const SampleTexels::Run* runs, uint32_t w0, uint32_t m, bool* exact) const {
#ifdef ST_STACK_MAP_POPCNT_CLONE
  if (__builtin_cpu_supports("popcnt")) return lit_samples_popcnt(runs, w0, m, exact);
#endif
  return lit_samples_body(runs, w0, m, exact);
}

void StackMap::soft_visibility(std::span<const Vec3d> points, std::span<float> out, bool* exact) const {
  // Each point's samples already go kGather at a time through lit_samples, whose phases
  // keep their loads in flight together; interleaving points on top (walk_interleave.hpp,
  // as before the gathered walks) would only add the lanes' bookkeeping.
  const size_t n = std::min(points.size(), out.size());
  for (size_t i = 0; i < n; ++i) out[i] = soft_visibility(points[i], exact);
}

float StackMap::filtered(const Vec3d& p, uint32_t w, uint32_t pcf_radius, float footprint, bool* exact) const {
  if (w >= grid_.slices) return 1.0f;
  const uint32_t n = grid_.geo.n;
  const LightSpace& ls = lights_[w];
  const LightPoint lp = ls.to_light(p);
  const float d = float(lp.d);
  const uint32_t r = 2 * std::min<uint32_t>(pcf_radius, (Evaluator::kMaxPcf - 1) / 2) + 1;
  FilterLevels f{n, n, 0.0f};
  if (footprint > 0) {
    // One finest texel's side in world units at p (a spot's grows with the distance).
    const double texel = ls.texel_size(p, n);
    f = filter_levels(n, float(double(footprint) / texel));
  }
  auto kernel = [&](uint32_t level) {
    const auto t = LightSpace::texel_of(level, lp.u, lp.v);
    if (r == 1) return d <= depth(t[0], t[1], w, level, exact) ? 1.0f : 0.0f;
    const uint64_t side = uint64_t(1) << level;
    uint32_t lit_taps = 0;
    for (uint32_t j = 0; j < r; ++j)
      for (uint32_t i = 0; i < r; ++i)
        lit_taps += d <= depth(pcf_tap(t[0], i, r, side), pcf_tap(t[1], j, r, side), w, level, exact);
    return float(lit_taps) / float(r * r);
  };
  const float a = kernel(f.fine);
  if (f.t == 0.0f) return a;
  return filter_blend(a, kernel(f.coarse), f.t);
}

float StackMap::visibility_filtered(const Vec3d& p, double time, uint32_t pcf_radius, float footprint,
                                    bool* exact) const {
  const uint32_t n = grid_.slices;
  const double s = std::clamp(std::isnan(time) ? 0.0 : time, 0.0, 1.0) * double(n - 1);
  const double near = std::nearbyint(s);
  if (std::fabs(s - near) <= 1e-9) return filtered(p, uint32_t(near), pcf_radius, footprint, exact);
  const uint32_t a = uint32_t(std::floor(s));
  const float f = float(s - double(a));
  const float va = filtered(p, a, pcf_radius, footprint, exact), vb = filtered(p, a + 1, pcf_radius, footprint, exact);
  return va + f * (vb - va);
}

float StackMap::soft_visibility_filtered(const Vec3d& p, uint32_t pcf_radius, float footprint, bool* exact) const {
  float sum = 0;
  for (uint32_t w = 0; w < grid_.slices; ++w) sum += filtered(p, w, pcf_radius, footprint, exact);
  return sum / float(grid_.slices);
}

}  // namespace st

#include "common/error.hpp"
#include "tiles/core/pack_reader.hpp"

namespace st {

ResidentStack::ResidentStack(const PackReader& pack) {
  const StackGrid* g = pack.stack();
  if (!g) throw Error(pack.name() + ": not a stack pack (no stack feature)");
  for (const TileIndexEntry& e : pack.tiles()) {
    uint64_t cell = 0;
    if (!g->cell_of(e.id, cell)) throw FormatError(pack.name() + ": " + describe_tile(e.id) + " names no stack cell");
    cells_.push_back(cell);
    buffers_.push_back(pack.read_raw(e.id));
    bytes_ += buffers_.back().size();
  }
  trees_.reserve(buffers_.size());
  for (size_t i = 0; i < buffers_.size(); ++i) {
    try {
      trees_.push_back(StackTile::open(buffers_[i]));
    } catch (const Error& err) {
      throw FormatError(pack.name() + ": " + describe_tile(pack.tiles()[i].id) + ": " + err.what());
    }
  }
  // One dense entry per cell: a lookup's tile is one load (a search over the cells was a
  // chain of cache misses per tile, which the soft lookups pay once per cell crossed).
  by_cell_.assign(g->entries.size(), StackTileRef());
  for (size_t i = 0; i < cells_.size(); ++i) {
    if (cells_[i] >= by_cell_.size()) throw FormatError(pack.name() + ": " + describe_tile(pack.tiles()[i].id) + " names no stack cell");
    by_cell_[cells_[i]] = trees_[i].ref();
  }
  map_ = std::make_unique<StackMap>(*g, [this](const uint64_t* cells, uint32_t n, StackTileRef* out) {
    for (uint32_t i = 0; i < n; ++i) out[i] = cells[i] < by_cell_.size() ? by_cell_[cells[i]] : StackTileRef();
  });
}

}  // namespace st
