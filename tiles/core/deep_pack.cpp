// The deep map of a pack: see deep_pack.hpp.
#include "tiles/core/deep_pack.hpp"

#include "common/error.hpp"
#include "tiles/core/pack_reader.hpp"
#include "tiles/core/tile_cut_grid.hpp"

namespace st {

std::unique_ptr<PackDeepMap> PackDeepMap::load(const PackReader& pack) {
  const DeepDirectory* dir = pack.deep_directory();
  if (!dir) return nullptr;
  std::unique_ptr<PackDeepMap> m(new PackDeepMap(*dir));
  const uint32_t t = dir->tiles_per_side();
  for (uint32_t ty = 0; ty < t; ++ty)
    for (uint32_t tx = 0; tx < t; ++tx) {
      if (!dir->has(tx, ty)) continue;
      const uint64_t id = dir->tile_id(tx, ty);
      m->tiles_.push_back(pack.read_raw(id));
      m->raw_bytes_ += m->tiles_.back().size();
      try {
        m->map_.add_tile(tx, ty, m->tiles_.back());
      } catch (const Error& e) {
        throw FormatError(pack.name() + ": " + describe_tile(id) + ": " + e.what());
      }
    }
  return m;
}

}  // namespace st
