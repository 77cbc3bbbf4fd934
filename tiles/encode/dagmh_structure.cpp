// Bottom-up DAG construction over a Hierarchy (DAG-MH §3.1, §3.2); see the header.
#include "tiles/encode/dagmh_structure.hpp"

#include <algorithm>
#include <bit>
#include <string>
#include <unordered_map>

#include "common/error.hpp"

namespace st::dagmh {
namespace {

// Treelet level and path of each of the 85 depth-first positions.
struct TreeletPos {
  uint32_t n = 0;
  uint32_t l[3] = {};
};
const std::array<TreeletPos, kTreeletNodes>& treelet_positions() {
  static const auto table = [] {
    std::array<TreeletPos, kTreeletNodes> t{};
    TreeletPos p;
    auto visit = [&](auto&& self, uint32_t n) -> void {
      t[treelet_position(n, p.l)] = p;
      if (n + 1 == kTreeletLevels) return;
      for (uint32_t c = 0; c < 4; ++c) {
        p.l[n] = c;
        p.n = n + 1;
        self(self, n + 1);
      }
      p.l[n] = 0;
      p.n = n;
    };
    visit(visit, 0);
    return t;
  }();
  return table;
}

void set_bit(TreeletBits& b, uint32_t p) { b[p >> 5] |= 1u << (p & 31); }

// Key interner: candidates found by hash, merged only on full key equality.
template <size_t N>
class Interner {
 public:
  explicit Interner(StructureHash hash) : hash_(hash) {}
  // Returns the id of `key`, adding it if new.
  uint32_t intern(const std::array<uint32_t, N>& key) {
    const uint64_t h = hash_(key.data(), N);
    auto [first, last] = by_hash_.equal_range(h);
    for (auto it = first; it != last; ++it)
      if (keys_[it->second] == key) return it->second;
    const uint32_t id = uint32_t(keys_.size());
    ST_CHECK(keys_.size() < kRefIndexMask);
    keys_.push_back(key);
    by_hash_.emplace(h, id);
    return id;
  }
  std::vector<std::array<uint32_t, N>>& keys() { return keys_; }

 private:
  StructureHash hash_;
  std::unordered_multimap<uint64_t, uint32_t> by_hash_;
  std::vector<std::array<uint32_t, N>> keys_;
};

// What the bottom-up pass keeps per hierarchy node of the level below.
struct Summary {
  uint32_t count = 0;   // values in the subtree
  uint32_t height = 0;  // levels below the node
  uint32_t inner = 0;   // inner id when height >= kTreeletLevels
  TreeletBits bits{};   // 4-level bitmap when height < kTreeletLevels
};

[[noreturn]] void bad(uint32_t level, size_t index, const std::string& what) {
  throw Error("dagmh: hierarchy level " + std::to_string(level) + " node " +
              std::to_string(index) + ": " + what);
}

}  // namespace

uint64_t default_structure_hash(const uint32_t* words, size_t count) {
  uint64_t h = 0x9E3779B97F4A7C15ull ^ count;
  for (size_t i = 0; i < count; ++i) {
    h ^= words[i];
    h *= 0xFF51AFD7ED558CCDull;
    h ^= h >> 32;
  }
  return h;
}

DagStructure build_structure(const Hierarchy& h, StructureHash hash) {
  if (h.levels.size() != size_t(h.depth) + 1 || h.levels[0].size() != 1)
    throw Error("dagmh: hierarchy must have depth + 1 levels and one root");
  if (!h.levels[0][0].has_value) bad(0, 0, "the root has no value");
  const auto& pos = treelet_positions();
  DagStructure out;
  Interner<5> inner(hash);                 // flags + 4 child ids
  Interner<kTreeletWords> treelets(hash);  // the bitmap
  std::vector<InnerNode> inner_nodes;      // parallel to inner.keys()
  std::vector<Summary> below, here;

  for (uint32_t level = h.depth + 1; level-- > 0;) {
    const auto& nodes = h.levels[level];
    here.assign(nodes.size(), Summary{});
    size_t next_child = 0;
    for (size_t j = 0; j < nodes.size(); ++j) {
      const HNode& node = nodes[j];
      if (j > 0 && !(nodes[j - 1].morton < node.morton)) bad(level, j, "nodes not in morton order");
      if (node.has_value && !(node.lo <= node.hi)) bad(level, j, "invalid interval");
      if (level == h.depth && node.child_mask) bad(level, j, "children below the finest level");
      Summary& s = here[j];
      uint64_t count = node.has_value ? 1 : 0;
      uint32_t present = 0, treelet_children = 0, height = 0;
      uint32_t child_refs[4] = {}, offsets[4] = {};
      uint32_t rank = 0;
      for (uint32_t c = 0; c < 4; ++c) {
        if (!((node.child_mask >> c) & 1)) continue;
        if (next_child >= below.size()) bad(level, j, "more children than the next level holds");
        if (h.levels[level + 1][next_child].morton != node.morton * 4 + c)
          bad(level, j, "child " + std::to_string(c) + " has the wrong morton code");
        const Summary& ch = below[next_child++];
        if (ch.count == 0) continue;  // no values below: irrelevant to every lookup
        present |= 1u << c;
        height = std::max(height, ch.height + 1);
        offsets[rank] = uint32_t(count);
        count += ch.count;
        if (count > 0xFFFFFFFFull) bad(level, j, "more than 2^32 values");
        ++rank;
      }
      s.count = uint32_t(count);
      s.height = height;
      if (count == 0) continue;
      if (height < kTreeletLevels) {  // a treelet: own bit + children's bitmaps one level down
        if (node.has_value) set_bit(s.bits, 0);
        size_t k = next_child - uint32_t(std::popcount(node.child_mask));
        for (uint32_t c = 0; c < 4; ++c) {
          if (!((node.child_mask >> c) & 1)) continue;
          const Summary& ch = below[k++];
          if (ch.count == 0) continue;
          for (uint32_t w = 0; w < kTreeletWords; ++w)
            for (uint32_t word = ch.bits[w]; word; word &= word - 1) {
              const uint32_t p = 32 * w + uint32_t(std::countr_zero(word));
              const TreeletPos& q = pos[p];  // q.n <= 2: the child has height <= 2
              const uint32_t path[3] = {c, q.l[0], q.l[1]};
              set_bit(s.bits, treelet_position(q.n + 1, path));
            }
        }
        continue;
      }
      // An inner node: its children become references (treelets interned here, where
      // each treelet is referenced once per tree edge).
      rank = 0;
      size_t k = next_child - uint32_t(std::popcount(node.child_mask));
      for (uint32_t c = 0; c < 4; ++c) {
        if (!((node.child_mask >> c) & 1)) continue;
        const Summary& ch = below[k++];
        if (ch.count == 0) continue;
        if (ch.height < kTreeletLevels) {
          treelet_children |= 1u << c;
          child_refs[rank] = treelets.intern(ch.bits);
          ++out.tree_treelets;
        } else {
          child_refs[rank] = ch.inner;
        }
        ++rank;
      }
      const uint32_t flags = present | (treelet_children << kNodeTreeletShift) |
                             (node.has_value ? kNodeValuedBit : 0);
      const std::array<uint32_t, 5> key = {flags, child_refs[0], child_refs[1], child_refs[2],
                                           child_refs[3]};
      s.inner = inner.intern(key);
      ++out.tree_inner;
      if (s.inner == inner_nodes.size()) {
        InnerNode n;
        n.flags = flags;
        std::copy(child_refs, child_refs + 4, n.child);
        std::copy(offsets, offsets + 4, n.value_offset);
        n.height = height;
        n.count = s.count;
        inner_nodes.push_back(n);
      }
    }
    if (next_child != below.size()) bad(level, nodes.size(), "next level has unclaimed nodes");
    std::swap(below, here);
  }

  const Summary& root = below[0];
  if (root.height < kTreeletLevels) {
    out.root = kRefTreelet | treelets.intern(root.bits);
    ++out.tree_treelets;
  } else {
    out.root = kRefInner | root.inner;
  }
  out.inner = std::move(inner_nodes);
  out.treelets = std::move(treelets.keys());

  // Values in depth-first (pre-)order, children in child order: the order the DAG's
  // value offsets and the treelet bitmaps count in (§3.1).
  const auto first_child = h.first_child_index();
  out.values.reserve(h.valued_count());
  std::vector<std::pair<uint32_t, uint32_t>> stack = {{0, 0}};
  while (!stack.empty()) {
    auto [level, j] = stack.back();
    stack.pop_back();
    const HNode& node = h.levels[level][j];
    if (node.has_value) out.values.push_back({node.lo, node.hi, node.value});
    const uint32_t n = uint32_t(std::popcount(node.child_mask));
    for (uint32_t k = n; k-- > 0;) stack.push_back({level + 1, first_child[level][j] + k});
  }
  return out;
}

}  // namespace st::dagmh
