// The deep tiles of a whole map: see deep_build.hpp.
#include "tiles/bake/deep_build.hpp"

#include "common/error.hpp"
#include "tiles/build/pack_writer.hpp"
#include "tiles/core/deep_format.hpp"
#include "tiles/core/deep_pack.hpp"

namespace st {

DeepMapBuild build_deep_tiles(const DeepSampler& sampler, uint32_t level, uint32_t side_bits,
                              const DeepSampleOptions& options, uint64_t max_tile_bytes) {
  if (side_bits > level || side_bits > deep::kMaxSideBits || level > kMaxLevel)
    throw Error("deep tiles: tiles of 2^" + std::to_string(side_bits) + " texels do not cut a level-" +
                std::to_string(level) + " map (at most 2^8 a side)");
  const uint32_t per_side_bits = level - side_bits;
  if (per_side_bits > 10) throw Error("deep tiles: more than 2^20 tiles; use larger tiles or a coarser level");
  const uint32_t t = 1u << per_side_bits, side = 1u << side_bits;
  DeepMapBuild out;
  out.level = level, out.side_bits = side_bits;
  for (uint32_t ty = 0; ty < t; ++ty)
    for (uint32_t tx = 0; tx < t; ++tx) {
      DeepSampleStats st;
      const DeepRegion r = sampler.trace({level, uint64_t(tx) * side, uint64_t(ty) * side, side, side},
                                         options, &st);
      out.sampling.texels += st.texels, out.sampling.rays += st.rays;
      out.sampling.crossings += st.crossings, out.sampling.volume_steps += st.volume_steps;
      out.sampling.vertices_in += st.vertices_in, out.sampling.vertices_out += st.vertices_out;
      out.sampling.monochrome += st.monochrome, out.sampling.seconds += st.seconds;
      bool any = false;
      for (const VisibilityFunction& f : r.functions) any = any || !f.vertices.empty();
      if (!any) {
        ++out.empty_tiles;
        continue;
      }
      DeepTileBytes tile{tx, ty, {}};
      try {
        tile.bytes = encode_deep_tile(r.functions, side_bits, options.effective_epsilon(), nullptr,
                                      max_tile_bytes);
      } catch (const Error& e) {
        throw Error("deep tile " + std::to_string(tx) + "," + std::to_string(ty) + " of level " +
                    std::to_string(level) + ": " + e.what());
      }
      out.bytes += tile.bytes.size();
      out.tiles.push_back(std::move(tile));
    }
  return out;
}

void append_deep_map(PackWriter& writer, const DeepMapBuild& map, double epsilon, uint32_t samples_per_side) {
  if (map.tiles.empty()) return;
  DeepDirectory dir = DeepDirectory::make(map.level, map.side_bits, float(epsilon), samples_per_side);
  for (const DeepTileBytes& t : map.tiles) {
    dir.set(t.tx, t.ty);
    writer.append_deep_tile(dir.tile_id(t.tx, t.ty), TileKind::deep, t.bytes);
  }
  writer.append_deep_tile(kDeepDirectoryId, TileKind::deep_directory, dir.serialize());
}

}  // namespace st
