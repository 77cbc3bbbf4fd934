// The deep tiles of a whole map: see deep_build.hpp.
#include "tiles/bake/deep_build.hpp"

#include "common/error.hpp"
#include "tiles/encode/pack_writer.hpp"
#include "tiles/core/deep_format.hpp"
#include "tiles/core/deep_pack.hpp"

namespace st {
namespace {

void check_cut(uint32_t level, uint32_t side_bits) {
  if (side_bits > level || side_bits > deep::kMaxSideBits || level > kMaxLevel)
    throw Error("deep tiles: tiles of 2^" + std::to_string(side_bits) + " texels do not cut a level-" +
                std::to_string(level) + " map (at most 2^8 a side)");
  if (level - side_bits > 10) throw Error("deep tiles: more than 2^20 tiles; use larger tiles or a coarser level");
}

// Encodes one tile's functions unless all are empty (then counted, not stored).
void add_tile(DeepMapBuild& out, uint32_t tx, uint32_t ty, std::span<const VisibilityFunction> functions,
              double epsilon, uint64_t max_tile_bytes) {
  bool any = false;
  for (const VisibilityFunction& f : functions) any = any || !f.vertices.empty();
  if (!any) {
    ++out.empty_tiles;
    return;
  }
  DeepTileBytes tile{tx, ty, {}};
  try {
    tile.bytes = encode_deep_tile(functions, out.side_bits, epsilon, nullptr, max_tile_bytes);
  } catch (const Error& e) {
    throw Error("deep tile " + std::to_string(tx) + "," + std::to_string(ty) + " of level " +
                std::to_string(out.level) + ": " + e.what());
  }
  out.bytes += tile.bytes.size();
  out.tiles.push_back(std::move(tile));
}

}  // namespace

DeepMapBuild deep_tiles_from_functions(const DeepRegion& map, uint32_t side_bits, double recompress_epsilon,
                                       double encode_epsilon, uint64_t max_tile_bytes) {
  const TraceRegion& r = map.region;
  check_cut(r.level, side_bits);
  const uint64_t n = uint64_t(1) << r.level;
  if (r.x0 != 0 || r.y0 != 0 || r.width != n || r.height != n || map.functions.size() != n * n)
    throw Error("deep tiles: the functions cover " + std::to_string(r.width) + "x" + std::to_string(r.height) +
                " texels at " + std::to_string(r.x0) + "," + std::to_string(r.y0) + ", not the whole " +
                std::to_string(n) + "^2 map of level " + std::to_string(r.level));
  const uint32_t t = 1u << (r.level - side_bits), side = 1u << side_bits;
  DeepMapBuild out;
  out.level = r.level, out.side_bits = side_bits;
  std::vector<VisibilityFunction> tile(size_t(side) * side);
  for (uint32_t ty = 0; ty < t; ++ty)
    for (uint32_t tx = 0; tx < t; ++tx) {
      for (uint32_t j = 0; j < side; ++j)
        for (uint32_t i = 0; i < side; ++i) {
          const uint64_t x = uint64_t(tx) * side + i, y = uint64_t(ty) * side + j;
          const VisibilityFunction& f = map.functions[y * n + x];
          const std::string at = "deep texel " + std::to_string(x) + "," + std::to_string(y) + ": ";
          if (const std::string why = f.check(); !why.empty()) throw Error(at + why);
          for (const VisVertex& v : f.vertices)
            if (!(v.depth >= 0 && v.depth <= 1))
              throw Error(at + "depth " + std::to_string(v.depth) +
                          " outside [0, 1] (depths must be the light-space d of this light)");
          VisibilityFunction& g = tile[size_t(j) * side + i];
          g = recompress_epsilon >= 0 ? compress(f, recompress_epsilon) : f;
          out.sampling.vertices_in += f.vertices.size(), out.sampling.vertices_out += g.vertices.size();
          out.sampling.monochrome += g.monochrome;
          ++out.sampling.texels;
        }
      add_tile(out, tx, ty, tile, encode_epsilon, max_tile_bytes);
    }
  return out;
}

DeepMapBuild build_deep_tiles(const DeepSampler& sampler, uint32_t level, uint32_t side_bits,
                              const DeepSampleOptions& options, uint64_t max_tile_bytes) {
  check_cut(level, side_bits);
  const uint32_t t = 1u << (level - side_bits), side = 1u << side_bits;
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
      add_tile(out, tx, ty, r.functions, options.effective_epsilon(), max_tile_bytes);
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
