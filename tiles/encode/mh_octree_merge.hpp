// The octree encoder's subtree merger (private to tiles/encode; MHOCT.md "Version 3, merged
// subtrees measured"): two nodes of one level whose children blocks have the same topology (child
// masks and kinds all the way down) and whose corresponding valued nodes admit a common
// value can point at one children block. The merger only chooses values: every node that
// ends up sharing is given the same value as its partners, one inside the intersection of
// the central windows (mh_internal.hpp `central_window`) of all the nodes it answers for,
// so the encoder's exact hash-consing then finds the blocks equal word for word and the
// format is unchanged (MMH's idea, mmh_merge.hpp, carried to the octree with absolute
// values; MH 2016 §3.1: any value inside a node's interval is lossless).
#pragma once
#include <cstdint>
#include <vector>

#include "tiles/encode/mh_octree_flat.hpp"

namespace st::moct_detail {

struct MergeCounts {
  uint64_t candidates = 0;    // distinct blocks tested (one per exactly-equal subtree set)
  uint64_t tests = 0;         // candidate pairs looked at
  uint64_t quick_rejects = 0; // pairs whose first valued descendants cannot meet
  uint64_t full_rejects = 0;  // pairs refused by the full comparison (or its budget)
  uint64_t merges = 0;        // pairs merged
  uint64_t values_changed = 0;  // nodes whose value moved
};

struct MergeLimits {
  uint32_t window = 64;      // later candidates of its group each candidate is tested against
  uint32_t max_pairs = 4096; // node pairs one full comparison may visit (bounded time)
};

// The window each node's value must stay in: for a valued node, central_window(lo, hi)
// where its value lies there (the builder's choice), else the point [value, value] (a
// hierarchy made by hand, or a tile root holding an inherited value); empty nodes
// [-inf, inf]. The merger keeps every value in its node's window and the encoder checks
// the encoded buffer against it.
void value_windows(const Flat& t, std::vector<float>& wlo, std::vector<float>& whi);

// Rewrites t.value so that compatible subtrees become equal (see the file comment).
// Deterministic (candidate order fixed by level, height, shape and node order; hash
// tables only map exact keys), each full comparison bounded by limits.max_pairs.
void merge_subtrees(Flat& t, const std::vector<float>& wlo, const std::vector<float>& whi, const MergeLimits& limits,
                    MergeCounts& counts);

}  // namespace st::moct_detail
