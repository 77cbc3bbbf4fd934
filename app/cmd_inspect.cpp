// shadowtile inspect: what a pack holds (header, features, tiles, sizes).
#include <cstdio>
#include <nlohmann/json.hpp>

#include "tiles/core/surface_extent.hpp"

#include "app/command.hpp"
#include "app/stack_cli.hpp"
#include "app/pack_cli_util.hpp"
#include "common/error.hpp"
#include "common/text.hpp"
#include "tiles/core/map_preview.hpp"
#include "tiles/core/pack_dictionary.hpp"
#include "tiles/core/pack_reader.hpp"

namespace st::cli {
namespace {

struct InspectArgs {
  std::string pack;
  bool json = false;
};

void run_inspect(const InspectArgs& a) {
  auto r = PackReader::open(a.pack);
  const auto& h = r->header();
  uint64_t constants = 0, tiles = 0, index = 0;
  for (auto& e : r->grid().entries) constants += e.kind == EntryKind::constant;
  uint64_t stored = 0, raw = 0, largest = 0, deep_tiles = 0, deep_stored = 0, deep_raw = 0;
  for (auto& t : r->tiles()) {
    if (is_deep_id(t.id)) {  // the deep part (tiles/PACK.md "Deep tiles"), shown apart
      deep_tiles += t.kind == TileKind::deep, deep_stored += t.stored_size, deep_raw += t.raw_size;
      continue;
    }
    (t.kind == TileKind::index ? index : tiles)++;
    stored += t.stored_size;
    raw += t.raw_size;
    largest = std::max<uint64_t>(largest, t.raw_size);
  }
  const uint64_t side = uint64_t(1) << h.map_level;
  const double raw_map = double(side) * double(side) * 4;
  nlohmann::json j;
  j["pack"] = a.pack;
  j["format_version"] = kPackVersion;
  j["resolution"] = side;
  j["map_level"] = h.map_level;
  j["skip_level"] = h.skip_level;
  j["encoding"] = to_string(h.encoding);
  j["light"] = r->light().spec().to_string();
  j["light_kind"] = light_kind_name(h.light_kind);
  {  // the light as client::LightTransform publishes it (MapInfo::light), and the scene's extent
    const LightSpace& l = r->light();
    auto vec = [](const Vec3d& v) { return nlohmann::json::array({v.x, v.y, v.z}); };
    j["light_transform"] = {{"kind", light_kind_name(l.kind())}, {"origin", vec(l.origin())},
                            {"axis_u", vec(l.axis_u())},      {"axis_v", vec(l.axis_v())},
                            {"forward", vec(l.forward())},    {"extent", l.extent_uv()},
                            {"near", l.near_plane()},         {"far", l.far_plane()},
                            {"array", l.to_array()}};
    if (!(h.flags & kFeatureStack)) {
      const SurfaceExtent e = surface_extent(l, r->grid());
      j["scene"] = {{"bounds_lo", vec(e.box.lo)}, {"bounds_hi", vec(e.box.hi)}, {"ground", e.ground},
                    {"top", e.top}, {"x0", e.x0}, {"x1", e.x1}, {"z0", e.z0}, {"z1", e.z1}, {"points", e.points}};
    }
  }
  j["tile_bytes"] = h.tile_bytes;
  char hash[32];
  std::snprintf(hash, sizeof hash, "%016llx", (unsigned long long)h.scene_hash);
  j["scene_hash"] = hash;
  j["features"] = feature_names(h.flags);
  j["file_bytes"] = r->file_size();
  j["grid_entries"] = r->grid().entries.size();
  j["constant_entries"] = constants;
  j["encoded_tiles"] = tiles;
  j["index_tiles"] = index;
  j["tile_stored_bytes"] = stored;
  j["tile_raw_bytes"] = raw;
  j["largest_tile_raw_bytes"] = largest;
  j["fraction_of_raw_float_map"] = double(r->file_size()) / raw_map;
  j["preview_levels"] = r->preview().levels();
  j["preview_bytes"] = r->preview().serialized_size();
  nlohmann::json params = nlohmann::json::object();
  for (auto& [k, v] : r->params()) params[k] = v;
  j["build_params"] = params;
  if (r->stack()) inspect_stack(*r, j, false);
  DictionaryCounts dict;
  uint64_t dict_stored = 0;
  if (r->dictionary()) {  // tiles/PACK.md "DAG-MH dictionary"
    dict = count_dictionary(*r->dictionary());
    // Stored as a zlib stream at the end of the (inflated) grid section, after the preview.
    dict_stored = r->grid_bytes().size() - CutGrid::serialized_size(h.skip_level) - r->preview().serialized_size() -
                  kPackDictionaryHeaderBytes;
    nlohmann::json d;
    d["bytes"] = dict.bytes;
    d["stored_bytes"] = dict_stored;
    d["inner_nodes"] = dict.nodes;
    d["node_words"] = dict.node_words;
    d["treelets"] = dict.treelets;
    d["crc32"] = hex32(dict.crc);
    j["dagmh_dictionary"] = d;
  }
  const DeepDirectory* dd = r->deep_directory();
  if (dd) {
    nlohmann::json d;
    d["level"] = dd->level;
    d["resolution"] = uint64_t(1) << dd->level;
    d["tile_side"] = 1u << dd->side_bits;
    d["tiles"] = deep_tiles;
    d["tiles_possible"] = uint64_t(dd->tiles_per_side()) * dd->tiles_per_side();
    d["epsilon"] = dd->epsilon;
    d["samples_per_side"] = dd->samples_per_side;
    d["stored_bytes"] = deep_stored;
    d["raw_bytes"] = deep_raw;
    j["deep"] = d;
  }
  if (a.json) {
    // Bytes that are not UTF-8 (a hostile pack's params) become U+FFFD instead of a throw.
    std::printf("%s\n", j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace).c_str());
    return;
  }
  std::printf("%s: shadowtile pack v%u\n", a.pack.c_str(), kPackVersion);
  std::printf("  map          %llu^2 (level %u), skip level %u (%zu entries, %.1f%% constant)\n",
              (unsigned long long)side, h.map_level, h.skip_level, r->grid().entries.size(),
              r->grid().entries.empty() ? 0.0 : 100.0 * double(constants) / double(r->grid().entries.size()));
  std::printf("  encoding     %s, tiles <= %u bytes\n", to_string(h.encoding).c_str(), h.tile_bytes);
  std::printf("  light        %s\n", r->light().spec().to_string().c_str());
  std::printf("  features     %s\n", feature_names(h.flags).c_str());
  std::printf("  scene hash   %s\n", hash);
  std::printf("  tiles        %llu encoded + %llu index, %.2f MiB stored (%.2f MiB raw, largest %llu B)\n",
              (unsigned long long)tiles, (unsigned long long)index, double(stored) / (1 << 20),
              double(raw) / (1 << 20), (unsigned long long)largest);
  std::printf("  map preview  %u levels below K (to level %u), %.1f KiB in the map info\n", r->preview().levels(),
              h.skip_level + r->preview().levels(), double(r->preview().serialized_size()) / 1024);
  if (r->dictionary())
    std::printf("  dictionary   DAG-MH, %.1f KiB (%.1f KiB stored in the map info): %llu inner nodes (%llu words), "
                "%llu treelets, CRC %s\n",
                double(dict.bytes) / 1024, double(dict_stored) / 1024, (unsigned long long)dict.nodes,
                (unsigned long long)dict.node_words,
                (unsigned long long)dict.treelets, hex32(dict.crc).c_str());
  if (dd)
    std::printf("  deep         %llu^2 (level %u), %llu of %llu tiles of %u^2 stored, epsilon %g, %u^2 samples a "
                "texel, %.2f MiB stored (%.2f MiB raw)\n",
                (unsigned long long)(uint64_t(1) << dd->level), dd->level, (unsigned long long)deep_tiles,
                (unsigned long long)(uint64_t(dd->tiles_per_side()) * dd->tiles_per_side()), 1u << dd->side_bits,
                double(dd->epsilon), dd->samples_per_side, double(deep_stored) / (1 << 20),
                double(deep_raw) / (1 << 20));
  std::printf("  file         %.2f MiB = %.5f%% of the raw float32 map (%.1f GiB)\n",
              double(r->file_size()) / (1 << 20), 100.0 * double(r->file_size()) / raw_map,
              raw_map / double(1ull << 30));
  if (r->stack()) inspect_stack(*r, j, true);
  // Build parameters are text from the file: escaped as the JSON output escapes them.
  for (auto& [k, v] : r->params())
    std::printf("  param        %s = %s\n", printable_text(k).c_str(), printable_text(v).c_str());
}

void setup_inspect(CLI::App& app) {
  auto a = std::make_shared<InspectArgs>();
  app.footer("Example:\n  shadowtile inspect city.pack --json");
  app.add_option("pack", a->pack, "Pack file")->required();
  app.add_flag("--json", a->json, "Print JSON instead of a table");
  app.callback([a]() { run_inspect(*a); });
}

Register reg_inspect{"inspect", "Show what a pack holds: header, features, tiles and sizes", setup_inspect};

}  // namespace
}  // namespace st::cli
