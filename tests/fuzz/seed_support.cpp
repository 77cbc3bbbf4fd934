// Seed inputs from the real encoders (seed_support.hpp).
#include "tests/fuzz/seed_support.hpp"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <unistd.h>

#include "proto/proto.hpp"
#include "common/error.hpp"
#include "tiles/core/light.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/encode/pack_writer.hpp"
#include "tiles/encode/tile_cut.hpp"
#include "tiles/core/tile_cut_grid.hpp"

namespace st::fuzz {

IntervalTile random_field(uint32_t level, FieldKind kind, std::mt19937_64& rng) {
  IntervalTile t;
  t.level = level;
  t.width = t.height = 1u << level;
  t.data.resize(size_t(t.width) * t.height);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  const float base = unit(rng) * 0.8f;
  // Block size for `blocks`: a few texels, so subtrees are constant at some levels only.
  const uint32_t block = 1u << (level > 1 ? rng() % level : 0);
  std::vector<float> block_values(64);
  for (float& v : block_values) v = unit(rng) < 0.25f ? kLitDepth : unit(rng) * 0.9f;
  for (uint32_t j = 0; j < t.height; ++j)
    for (uint32_t i = 0; i < t.width; ++i) {
      Interval& iv = t.at(i, j);
      switch (kind) {
        case FieldKind::flat:
          iv = {base, base};
          break;
        case FieldKind::noise: {
          const float lo = unit(rng) * 0.9f;
          iv = {lo, lo + unit(rng) * 0.05f};
          break;
        }
        case FieldKind::blocks: {
          const float v = block_values[((j / block) * 7 + (i / block) * 3) % block_values.size()];
          iv = {v, v == kLitDepth ? kLitDepth : v + 0.01f};
          break;
        }
        case FieldKind::slope: {
          const float v = base * 0.5f + 0.4f * float(i + 2 * j) / float(3 * t.width);
          iv = {v, v + 0.02f};
          break;
        }
      }
    }
  return t;
}

std::vector<Hierarchy> seed_hierarchies(uint32_t max_level, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<Hierarchy> out;
  for (uint32_t level = 0; level <= max_level; ++level)
    for (int k = 0; k < kFieldKinds; ++k) {
      const IntervalTile t = random_field(level, FieldKind(k), rng);
      out.push_back(build_hierarchy(t, (level + k) % 3 == 2 ? MhConstruction::top_down
                                                             : MhConstruction::bottom_up));
    }
  return out;
}

std::vector<Bytes> encoded_tiles(Encoding e, uint32_t max_level, uint64_t seed) {
  std::vector<Bytes> out;
  for (const Hierarchy& h : seed_hierarchies(max_level, seed)) out.push_back(encode(h, e));
  return out;
}

namespace {

Bytes read_whole_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw st::Error("seed pack: cannot read " + path);
  return Bytes(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

LightSpace seed_light() {
  return LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"),
                         Aabb{{-10, 0, -10}, {10, 5, 10}});
}

}  // namespace

std::vector<Bytes> pack_files(uint64_t seed) {
  std::mt19937_64 rng(seed);
  const std::filesystem::path dir = std::filesystem::temp_directory_path() /
                                    ("shadowtile_fuzz_seeds_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  std::vector<Bytes> out;
  int n = 0;
  for (Encoding e : {Encoding::mh, Encoding::mmh, Encoding::dagmh, Encoding::vsdag})
    for (uint32_t level : {2u, 3u, 5u})
      for (uint32_t tile_bytes : {kDefaultTileBytes, 256u}) {
        const FieldKind kind = FieldKind(n % kFieldKinds);
        const Hierarchy h = build_hierarchy(random_field(level, kind, rng));
        CutParams cut;
        cut.map_level = level;
        cut.skip_level = std::min<uint32_t>(level, 1 + n % 3);
        cut.tile_bytes = tile_bytes;
        cut.codec = TileCodec::of(e);
        PackParams pp = PackParams::from(seed_light(), cut);
        pp.scene_hash = 0x5eed0000u + uint64_t(n);
        pp.build_params = {{"scene", "fuzz_seed"}, {"seed", std::to_string(n)}};
        // Small DAG-MH tiles share subtrees: those packs carry the pack dictionary.
        pp.dagmh_dictionary = e == Encoding::dagmh && tile_bytes == 256u;
        const std::string path = (dir / ("seed" + std::to_string(n++) + ".pack")).string();
        write_pack(path, h, cut, pp);
        out.push_back(read_whole_file(path));
        std::filesystem::remove(path);
      }
  std::filesystem::remove_all(dir);
  return out;
}

std::vector<Bytes> message_frames(uint64_t seed) {
  using namespace st::proto;
  std::mt19937_64 rng(seed);
  Limits limits;
  limits.max_frame_bytes = kMinFrameBytes;
  limits.max_tiles_per_batch = 16;
  limits.max_in_flight = 8;
  Bytes tile(200);
  for (auto& b : tile) b = uint8_t(rng());
  std::array<uint8_t, kNonceBytes> nonce{};
  for (auto& b : nonce) b = uint8_t(rng());

  Stats stats;
  stats.counters = {{"connections", 3}, {"tiles_sent", 12345}};
  stats.histograms = {{"latency_us", {{10, 4}, {100, 9}, {1000, 1}}}};
  MapList list;
  list.maps = {{"city", 2, 12, 6, 40, 123456}, {"terrain.big", 0, 20, 8, 9000, 1u << 30}};
  GetTiles get;
  get.map_id = 7;
  get.tiles = {{make_tile_id(3, 1, 2), 5}, {make_tile_id(4, 0, 15), 0}};
  TileData data;
  data.meta.tile_id = make_tile_id(3, 1, 2);
  data.meta.map_id = 7;
  data.meta.uncompressed_size = 999;
  data.meta.payload_crc32 = crc32(tile);
  data.payload = tile;
  Cancel cancel;
  cancel.request_ids = {3, 4};
  cancel.map_id = 7;
  cancel.tile_ids = {make_tile_id(2, 1, 1)};
  MapInfo info;
  info.map_id = 7;
  info.pack_header.assign(tile.begin(), tile.begin() + 64);
  info.skip_grid.assign(tile.begin() + 64, tile.end());

  const std::vector<std::pair<Message, uint32_t>> messages = {
      {make_hello(limits, "fuzz-client"), 1},
      {HelloAck{kVersion1, 8, kMinFrameBytes, 16, 0, nonce, "fuzz-server"}, 1},
      {ErrorMessage{ErrorCode::unknown_tile, "no such tile"}, 2},
      {ListMaps{}, 3},
      {list, 3},
      {OpenMap{"city"}, 4},
      {info, 4},
      {get, 5},
      {data, 5},
      {TileError{make_tile_id(4, 0, 15), 7, ErrorCode::unknown_tile, "gone"}, 5},
      {cancel, 0},
      {Ping{0x0123456789abcdefull}, 6},
      {Pong{0x0123456789abcdefull, 42}, 6},
      {GetStats{}, 8},
      {stats, 8},
      {Auth{nonce, nonce}, 9},
      {AuthOk{nonce}, 9},
  };
  std::vector<Bytes> out;
  for (const auto& [m, request_id] : messages) {
    Bytes frame;
    const uint8_t flags = request_id == 0 ? 0 : kFlagFinal;
    const Status s = encode_message(m, request_id, flags, limits, frame);
    if (!s) throw st::Error("seed frame " + std::string(to_string(type_of(m))) + ": " + s.detail);
    out.push_back(std::move(frame));
  }
  return out;
}

}  // namespace st::fuzz
