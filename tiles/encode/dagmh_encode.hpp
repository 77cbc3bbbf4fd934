// DAG-MH encoder entry with statistics (the plain entry is st::encode_dagmh in
// tiles/core/encoding.hpp). Buffer layout: tiles/core/DAGMH.md.
#pragma once
#include <cstdint>
#include <vector>

#include "tiles/encode/dagmh_structure.hpp"
#include "tiles/encode/dagmh_values_encode.hpp"
#include "tiles/encode/hierarchy.hpp"

namespace st::dagmh {

struct EncodeStats {
  uint64_t tree_inner = 0, dag_inner = 0;        // inner nodes before / after sharing
  uint64_t tree_treelets = 0, dag_treelets = 0;  // treelets before / after sharing
  uint64_t value_count = 0;
  uint32_t skip_level = 0;
  uint64_t header_bytes = 0, skip_bytes = 0, node_bytes = 0, treelet_bytes = 0,
           chunk_bytes = 0, multiplier_bytes = 0, total_bytes = 0;
  ValueStats values;
};

// Encodes `h`; throws st::Error if the hierarchy is malformed or too big for the
// format (2^30 node words / treelets, 2^32 values or bytes). `stats` may be null.
std::vector<uint8_t> encode(const Hierarchy& h, EncodeStats* stats = nullptr,
                            StructureHash hash = default_structure_hash);

}  // namespace st::dagmh
