#include "common/hash.hpp"
#include "tiles/encode/mmh_merge.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <cstring>
#include <unordered_map>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "common/error.hpp"

namespace st::mhq {
namespace {

constexpr uint32_t kPathsCap = 64;  // hard bound of MergeOptions::max_paths (stack arrays)
// A merged pointer must reach from the mergee to the merger's block within 16 bits
// unscaled (the demo's "offset rejection"), with room for alignment padding; longer ones
// would force scaling (and padding) onto the deep levels, where blocks are many.
constexpr uint64_t kMergeReach = kMaxOffset - 4096;

struct Candidate {
  uint64_t hash;
  uint32_t height;
  uint32_t pre;
  uint32_t node;
};

// Quick reject data of a candidate: the interval of its first valued descendant in
// pre-order, relative and absolute. Every node between it and the candidate is empty,
// so its ancestor value is the candidate's children base. The relative interval is
// widened by 2^-20 of the magnitudes involved because the float rounding of the stored
// number and of the decoder's add admits a little more than the exact interval. A
// reject is always safe (only an accepted merge needs proof); the widening just keeps
// the merges that rounding makes possible.
// Kept as separate arrays (rel_lo_, rel_hi_, abs_lo_, abs_hi_ in candidate order) so the
// scan compares 4 candidates per SSE instruction.
struct ScanKey {
  float rel_lo, rel_hi, abs_lo, abs_hi;
};

constexpr uint8_t kBlocked = 1;  // dead: below a mergee, never emitted
constexpr uint8_t kMergee = 2, kMerger = 4;

struct Assign {
  uint32_t node;
  float stored;
  uint8_t absolute;
};

class Planner {
 public:
  Planner(const FlatTree& t, const MergeOptions& o, MergeStats& s) : t_(t), opt_(o), stats_(s) {
    opt_.max_paths = std::clamp<uint32_t>(opt_.max_paths, 2, kPathsCap);
  }

  EmitPlan run() {
    const size_t n = t_.size();
    plan_.relative = true;
    plan_.alive.assign(n, 1);
    plan_.block_owner.resize(n);
    for (uint32_t i = 0; i < n; ++i) plan_.block_owner[i] = i;
    plan_.block_parent_levels.assign(n, 0);
    plan_.stored.assign(n, 0);
    plan_.absolute.assign(n, 0);
    decoded_.assign(n, 0);
    base_.assign(n, 0);
    shared_.assign(n, 0);
    parent_.assign(n, 0);
    slot_.assign(n, 0);
    initial_values();
    shape();
    merge();
    verify();
    for (uint32_t i = 0; i < n; ++i) stats_.absolute_values += plan_.alive[i] && plan_.absolute[i];
    return std::move(plan_);
  }

 private:
  float child_base(uint32_t n) const { return t_.valued[n] ? decoded_[n] : base_[n]; }

  // Verifies candidate stored number `r` (relative) on every path; fills the decoded values.
  bool try_relative(const uint32_t* nodes, const float* bases, uint32_t k, float r, float* out) const {
    if (!std::isfinite(r)) return false;
    for (uint32_t p = 0; p < k; ++p) {
      const float v = mmh_add(bases[p], r);
      if (!(t_.lo[nodes[p]] <= v && v <= t_.hi[nodes[p]])) return false;
      out[p] = v;
    }
    return true;
  }

  // One stored number for corresponding valued nodes `nodes[0..k)` whose ancestors decode
  // to `bases`: relative mid-intersection first (most room for later merges), then its
  // rounded ends, then an absolute value in the intersection of the intervals.
  bool choose(const uint32_t* nodes, const float* bases, uint32_t k, Assign& a, float* out) const {
    double lo = -std::numeric_limits<double>::infinity(), hi = -lo;
    float alo = -std::numeric_limits<float>::infinity(), ahi = -alo;
    for (uint32_t p = 0; p < k; ++p) {
      lo = std::max(lo, double(t_.lo[nodes[p]]) - double(bases[p]));
      hi = std::min(hi, double(t_.hi[nodes[p]]) - double(bases[p]));
      alo = std::max(alo, t_.lo[nodes[p]]);
      ahi = std::min(ahi, t_.hi[nodes[p]]);
    }
    a.node = nodes[0];
    a.absolute = 0;
    if (lo <= hi + 1e-6 * (1.0 + std::fabs(lo))) {
      // Candidates in order, the rounded ends only when the middle fails.
      for (int c = 0; c < 5; ++c) {
        const float r = c == 0   ? float(0.5 * (lo + hi))
                        : c == 1 ? float(lo)
                        : c == 2 ? float(hi)
                        : c == 3 ? std::nextafter(float(lo), INFINITY)
                                 : std::nextafter(float(hi), -INFINITY);
        if (try_relative(nodes, bases, k, r, out)) {
          a.stored = r;
          return true;
        }
      }
    }
    if (alo <= ahi) {
      float v = float(0.5 * double(alo) + 0.5 * double(ahi));
      if (!(alo <= v && v <= ahi)) v = alo;
      a.stored = v;
      a.absolute = 1;
      for (uint32_t p = 0; p < k; ++p) out[p] = v;
      return true;
    }
    return false;
  }

  // Top-down: each value relative to its decoded ancestor if that decodes inside its
  // interval (trying the hierarchy's own value first), else absolute.
  void initial_values() {
    plan_.stored[0] = t_.value[0];
    plan_.absolute[0] = 1;
    decoded_[0] = t_.value[0];
    for (uint32_t n = 0; n < t_.size(); ++n) {
      if (!t_.mask[n]) continue;
      const float b = child_base(n);
      for (uint32_t slot = 0; slot < 4; ++slot) {
        if (!(t_.mask[n] >> slot & 1u)) continue;
        const uint32_t c = t_.child(n, slot);
        parent_[c] = n;
        slot_[c] = uint8_t(slot);
        base_[c] = b;
        if (!t_.valued[c]) continue;
        float v;
        const float r = t_.value[c] - b;
        if (try_relative(&c, &b, 1, r, &v)) {
          plan_.stored[c] = r;
          decoded_[c] = v;
          continue;
        }
        Assign a;
        ST_CHECK(choose(&c, &b, 1, a, &v));  // the absolute value always fits one interval
        plan_.stored[c] = a.stored;
        plan_.absolute[c] = a.absolute;
        decoded_[c] = v;
      }
    }
  }

  // Heights, shape hashes (the node's mask and its children's kinds and shapes; the
  // node's own kind is left out: it lives in the parent, not in the shared block) and
  // pre-order numbers; then the sorted candidate list.
  void shape() {
    const size_t n = t_.size();
    std::vector<uint8_t> height(n, 0);
    std::vector<uint64_t> hash(n, 0);
    std::vector<uint32_t> first_valued(n, 0);
    for (size_t i = n; i-- > 0;) {
      if (!t_.mask[i]) continue;
      uint64_t h = mix64(t_.code_mask(uint32_t(i)) + 1);
      uint32_t ht = 0;
      bool first = true;
      for (uint32_t slot = 0; slot < 4; ++slot) {
        if (!(t_.mask[i] >> slot & 1u)) continue;
        const uint32_t c = t_.child(uint32_t(i), slot);
        if (first) first_valued[i] = t_.valued[c] ? c : first_valued[c];
        first = false;
        if (t_.mask[c]) {
          h = mix64(h ^ (hash[c] + slot));
          ht = std::max<uint32_t>(ht, height[c]);
        }
      }
      hash[i] = h;
      height[i] = uint8_t(ht + 1);
    }
    pre_.assign(n, 0);
    uint32_t counter = 0;
    std::vector<uint32_t> stack{0};
    while (!stack.empty()) {
      const uint32_t i = stack.back();
      stack.pop_back();
      pre_[i] = counter++;
      for (uint32_t slot = 4; slot-- > 0;)
        if (t_.mask[i] >> slot & 1u) stack.push_back(t_.child(i, slot));
    }
    for (uint32_t i = 1; i < n; ++i) {
      if (!t_.mask[i] || height[i] > opt_.max_height) continue;
      cands_.push_back({hash[i], height[i], pre_[i], i});
    }
    std::sort(cands_.begin(), cands_.end(), [](const Candidate& a, const Candidate& b) {
      if (a.height != b.height) return a.height > b.height;  // big subtrees first
      if (a.hash != b.hash) return a.hash < b.hash;
      return a.pre < b.pre;
    });
    stats_.candidates = cands_.size();
    std::vector<uint32_t> block0;
    unscaled_layout(t_, pos0_, block0);
    cand_of_.assign(n, ~0u);
    rel_lo_.resize(cands_.size());
    rel_hi_.resize(cands_.size());
    abs_lo_.resize(cands_.size());
    abs_hi_.resize(cands_.size());
    block0_.resize(cands_.size());
    state_.assign(cands_.size(), 0);
    for (uint32_t c = 0; c < cands_.size(); ++c) {
      const uint32_t i = cands_[c].node, f = first_valued[i];
      const double b = child_base(i), lo = t_.lo[f], hi = t_.hi[f];
      const double slack = 0x1p-20 * (std::fabs(b) + std::fabs(lo) + std::fabs(hi)) + 0x1p-126;
      rel_lo_[c] = float(lo - b - slack);
      rel_hi_[c] = float(hi - b + slack);
      abs_lo_[c] = t_.lo[f];
      abs_hi_[c] = t_.hi[f];
      block0_[c] = block0[i];
      cand_of_[i] = c;
    }
  }

  // Candidates b in [b0, b0 + n) (n <= 32) that pass the quick reject against `a` and are
  // neither dead nor mergees, as a bit mask. Nearly every test is a reject, so the scan
  // is this function: 4 candidates per SSE2 step where available.
  uint32_t scan_chunk(const ScanKey& a, size_t b0, size_t n) const {
    uint32_t mask = 0;
    size_t k = 0;
#if defined(__SSE2__)
    const __m128 a_rl = _mm_set1_ps(a.rel_lo), a_rh = _mm_set1_ps(a.rel_hi);
    const __m128 a_al = _mm_set1_ps(a.abs_lo), a_ah = _mm_set1_ps(a.abs_hi);
    for (; k + 4 <= n; k += 4) {
      const size_t b = b0 + k;
      const __m128 rel_apart = _mm_or_ps(_mm_cmplt_ps(a_rh, _mm_loadu_ps(&rel_lo_[b])),
                                         _mm_cmplt_ps(_mm_loadu_ps(&rel_hi_[b]), a_rl));
      const __m128 abs_apart = _mm_or_ps(_mm_cmplt_ps(a_ah, _mm_loadu_ps(&abs_lo_[b])),
                                         _mm_cmplt_ps(_mm_loadu_ps(&abs_hi_[b]), a_al));
      const uint32_t rejected = uint32_t(_mm_movemask_ps(_mm_and_ps(rel_apart, abs_apart)));
      uint32_t st;
      std::memcpy(&st, &state_[b], 4);
      st &= 0x01010101u * (kBlocked | kMergee);
      st = (st | (st >> 1)) & 0x01010101u;                  // byte j: 1 if unusable
      const uint32_t unusable = ((st * 0x01020408u) >> 24) & 0xFu;  // gather the 4 bits
      mask |= (~(rejected | unusable) & 0xFu) << k;
    }
#endif
    for (; k < n; ++k) {
      const size_t b = b0 + k;
      const bool rel_apart = (a.rel_hi < rel_lo_[b]) | (rel_hi_[b] < a.rel_lo);
      const bool abs_apart = (a.abs_hi < abs_lo_[b]) | (abs_hi_[b] < a.abs_lo);
      const bool usable = (state_[b] & (kBlocked | kMergee)) == 0;
      mask |= uint32_t(!(rel_apart & abs_apart) & usable) << k;
    }
    return mask;
  }

  // Lock-step walk of the block below the merger (nodes[0]) and the corresponding
  // nodes of every path; the last path is the candidate, whose topology is compared.
  bool compare(const uint32_t* nodes, const float* bases, uint32_t k) {
    const uint32_t nj = nodes[0], ni = nodes[k - 1];
    if (t_.mask[ni] != t_.mask[nj]) return false;
    for (uint32_t slot = 0; slot < 4; ++slot) {
      if (!(t_.mask[nj] >> slot & 1u)) continue;
      uint32_t child[kPathsCap];
      float child_bases[kPathsCap];
      for (uint32_t p = 0; p < k; ++p) child[p] = t_.child(nodes[p], slot);
      const uint32_t cj = child[0], ci = child[k - 1];
      if (t_.valued[ci] != t_.valued[cj] || t_.mask[ci] != t_.mask[cj]) return false;
      if (t_.valued[cj]) {
        Assign a;
        if (!choose(child, bases, k, a, child_bases)) return false;
        scratch_.push_back(a);
      } else {
        std::copy(bases, bases + k, child_bases);
      }
      if (t_.mask[cj] && !compare(child, child_bases, k)) return false;
    }
    return true;
  }

  void mark_subtree(uint32_t root, std::vector<uint8_t>& flags, bool block_candidates) {
    std::vector<uint32_t> stack;
    for (uint32_t slot = 0; slot < 4; ++slot)
      if (t_.mask[root] >> slot & 1u) stack.push_back(t_.child(root, slot));
    while (!stack.empty()) {
      const uint32_t i = stack.back();
      stack.pop_back();
      flags[i] = 1;
      if (block_candidates && cand_of_[i] != ~0u) state_[cand_of_[i]] |= kBlocked;
      for (uint32_t slot = 0; slot < 4; ++slot)
        if (t_.mask[i] >> slot & 1u) stack.push_back(t_.child(i, slot));
    }
  }

  struct PathState {
    uint32_t orig;  // the original node this path reaches
    float dval;     // decoded value of its nearest valued ancestor-or-self on this path
  };

  // Appends every root path into emitted node e (its own path first). Outside shared
  // blocks that is e alone with its initial decoded values (values change only inside
  // shared blocks); inside, the paths of the block's parent and of each of its mergees,
  // one step down, decoded with the current stored numbers. False past the path limit.
  bool paths_of(uint32_t e, std::vector<PathState>& out) const {
    if (!shared_[e]) {
      out.push_back({e, child_base(e)});
      return out.size() <= opt_.max_paths;
    }
    std::vector<PathState> up;
    const uint32_t p = parent_[e];
    if (!paths_of(p, up)) return false;
    auto it = mergees_.find(p);
    if (it != mergees_.end())
      for (uint32_t m : it->second)
        if (!paths_of(m, up)) return false;
    for (const PathState& s : up) {
      float d = s.dval;
      if (t_.valued[e]) d = plan_.absolute[e] ? plan_.stored[e] : mmh_add(s.dval, plan_.stored[e]);
      out.push_back({t_.child(s.orig, slot_[e]), d});
      if (out.size() > opt_.max_paths) return false;
    }
    return true;
  }

  // Paths into j's block: j's own, its mergees', then the candidate's (its own path
  // last: compare() checks the topology of the last path against the first).
  bool try_merge(uint32_t i, uint32_t j) {
    ST_CHECK(plan_.block_owner[j] == j && !dead_[j] && plan_.block_owner[i] == i && !dead_[i]);
    paths_.clear();
    if (!paths_of(j, paths_)) return false;
    auto found = mergees_.find(j);
    if (found != mergees_.end())
      for (uint32_t m : found->second)
        if (!paths_of(m, paths_)) return false;
    const size_t first_i = paths_.size();
    if (!paths_of(i, paths_)) return false;
    std::swap(paths_[first_i], paths_.back());
    const uint32_t k = uint32_t(paths_.size());
    uint32_t roots[kPathsCap];
    float bases[kPathsCap];
    for (uint32_t p = 0; p < k; ++p) roots[p] = paths_[p].orig, bases[p] = paths_[p].dval;
    scratch_.clear();
    if (!compare(roots, bases, k)) return false;
    for (const Assign& a : scratch_) {
      plan_.stored[a.node] = a.stored;
      plan_.absolute[a.node] = a.absolute;
    }
    if (found == mergees_.end()) mark_subtree(j, shared_, false);
    mergees_[j].push_back(i);
    mark_subtree(i, dead_, true);
    plan_.block_owner[i] = j;
    state_[cand_of_[i]] |= kMergee;
    state_[cand_of_[j]] |= kMerger;
    plan_.block_parent_levels[j] |= (1u << t_.level[j]) | (1u << t_.level[i]);
    ++stats_.merges;
    stats_.cross_level_merges += t_.level[i] != t_.level[j];
    return true;
  }

  void merge() {
    dead_.assign(t_.size(), 0);
    size_t g0 = 0;
    while (g0 < cands_.size()) {
      size_t g1 = g0 + 1;
      while (g1 < cands_.size() && cands_[g1].height == cands_[g0].height && cands_[g1].hash == cands_[g0].hash)
        ++g1;
      size_t reach_end = g0;
      uint64_t tests = 0, passed = 0;
      for (size_t a = g0; a + 1 < g1; ++a) {
        const uint32_t i = cands_[a].node;
        const uint64_t from = pos0_[i];
        // Blocks are laid out in pre-order, so the candidates within reach of this one's
        // pointer end at a position that only moves forward.
        while (reach_end < g1 && block0_[reach_end] - from <= kMergeReach) ++reach_end;
        if (state_[a]) continue;  // a mergee is neither blocked, merged nor a merger
        const size_t end = std::min<size_t>(reach_end, a + 1 + opt_.window);
        const ScanKey key_a{rel_lo_[a], rel_hi_[a], abs_lo_[a], abs_hi_[a]};
        size_t scanned_to = end;
        bool merged = false;
        for (size_t b0 = a + 1; b0 < end && !merged; b0 += 32) {
          uint32_t mask = scan_chunk(key_a, b0, std::min<size_t>(32, end - b0));
          while (mask) {
            const size_t b = b0 + size_t(__builtin_ctz(mask));
            mask &= mask - 1;
            ++passed;
            if (try_merge(i, cands_[b].node)) {
              merged = true;
              scanned_to = b + 1;
              break;
            }
            ++stats_.full_rejects;
          }
        }
        tests += scanned_to - (a + 1);
      }
      stats_.tests += tests;
      stats_.quick_rejects += tests - passed;
      g0 = g1;
    }
    for (uint32_t i = 0; i < t_.size(); ++i) {
      plan_.alive[i] = !dead_[i];
      stats_.nodes_removed += dead_[i];
    }
  }

  // Decodes every node of the original tree the way the reader will (through shared
  // blocks, with each path's own ancestors) and checks its interval: the lossless
  // invariant of the whole plan, always on.
  void verify() const {
    struct Item {
      uint32_t orig, emitted;
      float base;
    };
    std::vector<Item> stack{{0, 0, t_.value[0]}};
    ST_CHECK(plan_.absolute[0] && plan_.stored[0] == t_.value[0]);
    while (!stack.empty()) {
      const Item it = stack.back();
      stack.pop_back();
      if (!t_.mask[it.orig]) continue;
      const uint32_t owner = plan_.block_owner[it.emitted];
      ST_CHECK(t_.mask[owner] == t_.mask[it.orig] && plan_.alive[owner]);
      for (uint32_t slot = 0; slot < 4; ++slot) {
        if (!(t_.mask[it.orig] >> slot & 1u)) continue;
        const uint32_t o = t_.child(it.orig, slot), e = t_.child(owner, slot);
        ST_CHECK(t_.valued[o] == t_.valued[e] && plan_.alive[e]);
        float v = it.base;
        if (t_.valued[e]) {
          v = plan_.absolute[e] ? plan_.stored[e] : mmh_add(it.base, plan_.stored[e]);
          if (!(t_.lo[o] <= v && v <= t_.hi[o]))
            throw Error("MMH: internal error: node " + std::to_string(o) + " decodes outside its interval");
        }
        stack.push_back({o, e, v});
      }
    }
  }

  const FlatTree& t_;
  MergeOptions opt_;
  MergeStats& stats_;
  EmitPlan plan_;
  std::vector<float> decoded_, base_;
  std::vector<uint8_t> shared_, dead_;  // below a merger / below a mergee
  std::vector<uint32_t> parent_;
  std::vector<uint8_t> slot_;
  std::vector<PathState> paths_;
  std::vector<uint32_t> pre_, pos0_, cand_of_;
  std::vector<Candidate> cands_;
  std::vector<float> rel_lo_, rel_hi_, abs_lo_, abs_hi_;  // scanned data, candidate order
  std::vector<uint32_t> block0_;
  std::vector<uint8_t> state_;
  std::unordered_map<uint32_t, std::vector<uint32_t>> mergees_;
  std::vector<Assign> scratch_;
};

}  // namespace

EmitPlan plan_mmh(const FlatTree& t, const MergeOptions& options, MergeStats* stats) {
  MergeStats local;
  return Planner(t, options, stats ? *stats : local).run();
}

}  // namespace st::mhq
