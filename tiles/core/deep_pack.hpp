// The deep map of a pack (tiles/PACK.md "Deep tiles"; the directory that says which deep
// tiles a pack holds is deep_directory.hpp).
#pragma once
#include <cstdint>
#include <memory>
#include <vector>

#include "tiles/core/deep_directory.hpp"
#include "tiles/core/deep_map.hpp"

namespace st {

class PackReader;

// The deep map of a pack, held in memory (tools, tests, `verify`, a local renderer): every
// deep tile read (CRC checked), inflated and opened. Null from load() when the pack has
// no deep_shadow feature.
class PackDeepMap {
 public:
  static std::unique_ptr<PackDeepMap> load(const PackReader& pack);
  const DeepDirectory& directory() const { return dir_; }
  const DeepMap& map() const { return map_; }
  uint64_t raw_bytes() const { return raw_bytes_; }

 private:
  PackDeepMap(DeepDirectory dir) : dir_(std::move(dir)), map_(dir_.level, dir_.side_bits) {}
  DeepDirectory dir_;
  DeepMap map_;
  std::vector<std::vector<uint8_t>> tiles_;  // the bytes map_ borrows
  uint64_t raw_bytes_ = 0;
};

}  // namespace st
