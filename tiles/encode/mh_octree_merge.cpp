// The subtree merger (mh_octree_merge.hpp). Steps:
// 1. Exact hash-consing of the subtrees (kind, value, mask, children's ids; ids, never
//    hashes, are compared): nodes that are already equal get one id, and every later step
//    works on ids, so equal subtrees stay equal whatever values they move to. An id's
//    window is the intersection of its nodes' windows (all hold its value).
// 2. Candidates: the ids with children below the root, grouped by level and a hash of the
//    block's shape (the children's masks and kinds all the way down), largest subtrees
//    first (MMH's order, mmh_merge.hpp: big blocks save most and are merged before small
//    merges narrow the windows), in node order inside a group (neighbours in space).
// 3. Each candidate is tested against the next `window` candidates of its group: a quick
//    reject when the windows of the two blocks' first valued nodes do not meet, then a
//    full lock-step comparison of the two blocks that unites corresponding ids into
//    classes (union-find with an undo log) while the classes' windows still intersect,
//    refusing a topology mismatch and rolling back on failure. Invariant: two ids of one
//    class have subtrees whose corresponding ids are all of one class; so a class pair
//    met again needs no walk, and the blocks of two merged candidates end up equal once
//    every class holds one value. A candidate's own id is not united with its partner's
//    (its value lives in its parent's block, not in the one shared).
// 4. Each class of more than one id takes roundest_in of its window (the roundest float
//    every node of it admits, as central_roundest picks for one node); the others keep
//    their value.
#include "tiles/encode/mh_octree_merge.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <limits>
#include <unordered_map>

#include "common/error.hpp"
#include "common/hash.hpp"
#include "tiles/encode/mh_internal.hpp"

namespace st::moct_detail {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
using Key = std::array<uint32_t, 11>;

constexpr uint32_t kSignature = 4;  // values that order candidates inside a group

struct Candidate {
  uint64_t shape;
  uint32_t height, level, node, id;
  std::array<float, kSignature> sig;  // the block's first valued nodes' values (see candidates())
};

class Merger {
 public:
  Merger(Flat& t, const std::vector<float>& wlo, const std::vector<float>& whi, const MergeLimits& lim, MergeCounts& c)
      : t_(t), wlo_(wlo), whi_(whi), lim_(lim), counts_(c) {}

  void run() {
    hash_cons();
    candidates();
    merge();
    assign();
  }

 private:
  // Step 1. Nodes are visited last to first, so children get their ids before parents
  // and every child id is smaller than its parent's.
  void hash_cons() {
    std::unordered_map<Key, uint32_t, mh_detail::WordKeyHash> ids;
    id_.assign(t_.size(), 0);
    for (uint32_t n = uint32_t(t_.size()); n-- > 0;) {
      Key key{};
      key[0] = t_.mask[n] | uint32_t(t_.level[n]) << 8;
      key[1] = t_.valued[n];
      key[2] = t_.valued[n] ? moct::float_bits(t_.value[n]) : 0u;
      const uint32_t c0 = t_.first_child[n], cn = t_.children(n);
      for (uint32_t i = 0; i < cn; ++i) key[3 + i] = id_[c0 + i] + 1;
      const auto [it, fresh] = ids.try_emplace(key, uint32_t(rep_.size()));
      const uint32_t id = it->second;
      id_[n] = id;
      if (fresh) {
        rep_.push_back(n);
        child_begin_.push_back(uint32_t(child_ids_.size()));
        for (uint32_t i = 0; i < cn; ++i) child_ids_.push_back(id_[c0 + i]);
        lo_.push_back(wlo_[n]), hi_.push_back(whi_[n]);
      } else {
        lo_[id] = std::max(lo_[id], wlo_[n]), hi_[id] = std::min(hi_[id], whi_[n]);
      }
    }
    const size_t ids_n = rep_.size();
    parent_.resize(ids_n), size_.assign(ids_n, 1);
    for (uint32_t i = 0; i < ids_n; ++i) parent_[i] = i;
    class_lo_ = lo_, class_hi_ = hi_;
  }

  uint32_t mask(uint32_t id) const { return t_.mask[rep_[id]]; }
  bool valued(uint32_t id) const { return t_.valued[rep_[id]] != 0; }
  uint32_t kind(uint32_t id) const { return t_.kind(rep_[id]); }

  // Step 2.
  void candidates() {
    const size_t ids_n = rep_.size();
    std::vector<uint64_t> shape(ids_n, 0);
    std::vector<uint8_t> height(ids_n, 0);
    std::vector<uint32_t> first_valued(ids_n, 0);
    for (uint32_t id = 0; id < ids_n; ++id) {  // children first (see hash_cons)
      const uint32_t m = mask(id);
      if (!m) continue;
      uint64_t h = mix64(uint64_t(t_.code_mask(rep_[id])) + 1);
      uint32_t ht = 0;
      const uint32_t* ch = &child_ids_[child_begin_[id]];
      first_valued[id] = valued(ch[0]) ? ch[0] : first_valued[ch[0]];
      for (uint32_t i = 0, cn = uint32_t(std::popcount(m)); i < cn; ++i) {
        if (!mask(ch[i])) continue;
        h = mix64(h ^ (shape[ch[i]] + i));
        ht = std::max<uint32_t>(ht, height[ch[i]]);
      }
      shape[id] = h, height[id] = uint8_t(ht + 1);
      if (t_.level[rep_[id]] == 0) continue;
      Candidate c{h, height[id], t_.level[rep_[id]], rep_[id], id, {}};
      for (uint32_t i = 0, cn = uint32_t(std::popcount(m)), k = 0; i < cn && k < kSignature; ++i)
        c.sig[k++] = t_.value[rep_[valued(ch[i]) ? ch[i] : first_valued[ch[i]]]];
      cands_.push_back(c);
    }
    // Inside a group (one level, height and shape) candidates are ordered by the values
    // of their children (an empty child: its first valued descendant's), so blocks whose
    // values can meet lie close together in the order and within each other's window.
    std::sort(cands_.begin(), cands_.end(), [](const Candidate& a, const Candidate& b) {
      if (a.height != b.height) return a.height > b.height;  // big blocks first
      if (a.level != b.level) return a.level < b.level;
      if (a.shape != b.shape) return a.shape < b.shape;
      if (a.sig != b.sig) return a.sig < b.sig;
      return a.node < b.node;
    });
    quick_lo_.resize(cands_.size()), quick_hi_.resize(cands_.size());
    for (size_t c = 0; c < cands_.size(); ++c) {
      const uint32_t f = first_valued[cands_[c].id];
      quick_lo_[c] = lo_[f], quick_hi_[c] = hi_[f];
    }
    counts_.candidates = cands_.size();
  }

  uint32_t find(uint32_t x) const {
    while (parent_[x] != x) x = parent_[x];
    return x;
  }

  struct Undo {
    uint32_t child, root, size;
    float lo, hi;
  };

  void unite(uint32_t a, uint32_t b, float lo, float hi) {
    if (size_[a] < size_[b]) std::swap(a, b);
    log_.push_back({b, a, size_[a], class_lo_[a], class_hi_[a]});
    parent_[b] = a, size_[a] += size_[b], class_lo_[a] = lo, class_hi_[a] = hi;
  }

  void rollback(size_t mark) {
    while (log_.size() > mark) {
      const Undo& u = log_.back();
      parent_[u.child] = u.child, size_[u.root] = u.size, class_lo_[u.root] = u.lo, class_hi_[u.root] = u.hi;
      log_.pop_back();
    }
  }

  // Lock-step comparison of the blocks of ids a and b (same level), uniting corresponding
  // children; false on a mismatch, an empty window intersection or past the budget.
  bool compare(uint32_t a, uint32_t b) {
    if (mask(a) != mask(b)) return false;
    const uint32_t* ca = &child_ids_[child_begin_[a]];
    const uint32_t* cb = &child_ids_[child_begin_[b]];
    for (uint32_t i = 0, cn = uint32_t(std::popcount(mask(a))); i < cn; ++i) {
      if (++pairs_ > lim_.max_pairs) return false;
      const uint32_t x = ca[i], y = cb[i];
      const uint32_t rx = find(x), ry = find(y);
      if (rx == ry) continue;  // one class: equal classes all the way down (invariant)
      if (kind(x) != kind(y)) return false;
      const float lo = std::max(class_lo_[rx], class_lo_[ry]), hi = std::min(class_hi_[rx], class_hi_[ry]);
      if (!(lo <= hi)) return false;
      unite(rx, ry, lo, hi);
      if (mask(x) && !compare(x, y)) return false;
    }
    return true;
  }

  // Step 3.
  void merge() {
    std::vector<uint8_t> joined(cands_.size(), 0);
    size_t g0 = 0;
    while (g0 < cands_.size()) {
      size_t g1 = g0 + 1;
      while (g1 < cands_.size() && cands_[g1].height == cands_[g0].height && cands_[g1].level == cands_[g0].level &&
             cands_[g1].shape == cands_[g0].shape)
        ++g1;
      for (size_t a = g0; a + 1 < g1; ++a) {
        if (joined[a]) continue;  // its block already joined an earlier candidate's
        const size_t end = std::min<size_t>(g1, a + 1 + lim_.window);
        for (size_t b = a + 1; b < end; ++b) {
          ++counts_.tests;
          if (quick_hi_[a] < quick_lo_[b] || quick_hi_[b] < quick_lo_[a]) {
            ++counts_.quick_rejects;
            continue;
          }
          const size_t mark = log_.size();
          pairs_ = 0;
          if (!compare(cands_[a].id, cands_[b].id)) {
            rollback(mark);
            ++counts_.full_rejects;
            continue;
          }
          joined[b] = 1;
          counts_.merges += log_.size() > mark;
          log_.clear();  // committed
        }
      }
      g0 = g1;
    }
  }

  // Step 4.
  void assign() {
    std::vector<float> value(rep_.size()), class_value(rep_.size());
    std::vector<uint8_t> chosen(rep_.size(), 0);
    for (uint32_t id = 0; id < rep_.size(); ++id) {
      value[id] = t_.value[rep_[id]];
      if (!valued(id)) continue;
      const uint32_t r = find(id);
      if (size_[r] == 1) continue;
      if (!chosen[r]) chosen[r] = 1, class_value[r] = mh_detail::roundest_in(class_lo_[r], class_hi_[r]);
      value[id] = class_value[r];
      // Always on: the class window lies inside this id's (and so every node's of it).
      if (!(lo_[id] <= value[id] && value[id] <= hi_[id]))
        throw Error("MH octree merge: internal error: a merged value leaves its window");
    }
    for (uint32_t n = 0; n < t_.size(); ++n) {
      if (!t_.valued[n]) continue;
      const float v = value[id_[n]];
      counts_.values_changed += moct::float_bits(v) != moct::float_bits(t_.value[n]);
      t_.value[n] = v;
    }
  }

  Flat& t_;
  const std::vector<float>& wlo_;
  const std::vector<float>& whi_;
  MergeLimits lim_;
  MergeCounts& counts_;
  std::vector<uint32_t> id_;                     // per node
  std::vector<uint32_t> rep_, child_begin_;      // per id: its first node, its children in child_ids_
  std::vector<uint32_t> child_ids_;
  std::vector<float> lo_, hi_;                   // per id: its window
  std::vector<uint32_t> parent_, size_;          // union-find over ids
  std::vector<float> class_lo_, class_hi_;       // per class root: the intersection of its ids' windows
  std::vector<Undo> log_;
  std::vector<Candidate> cands_;
  std::vector<float> quick_lo_, quick_hi_;       // candidate order: its first valued node's window
  uint32_t pairs_ = 0;
};

}  // namespace

void value_windows(const Flat& t, std::vector<float>& wlo, std::vector<float>& whi) {
  wlo.assign(t.size(), -kInf), whi.assign(t.size(), kInf);
  for (size_t n = 0; n < t.size(); ++n) {
    if (!t.valued[n]) continue;
    float l = t.value[n], h = t.value[n];
    if (t.lo[n] <= t.hi[n]) mh_detail::central_window(t.lo[n], t.hi[n], l, h);
    const float v = t.value[n];
    if (!(l <= v && v <= h)) l = h = v;
    wlo[n] = l, whi[n] = h;
  }
}

void merge_subtrees(Flat& t, const std::vector<float>& wlo, const std::vector<float>& whi, const MergeLimits& limits,
                    MergeCounts& counts) {
  Merger(t, wlo, whi, limits, counts).run();
}

}  // namespace st::moct_detail
