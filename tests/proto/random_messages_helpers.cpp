// Seeded generators of valid random messages (see random_messages.hpp).
#include "random_messages.hpp"

#include <algorithm>
#include <set>
#include <stdexcept>

namespace st::proto::test {
namespace {

template <class T>
T uniform(Rng& rng, T lo, T hi) {
  return static_cast<T>(std::uniform_int_distribution<std::uint64_t>(lo, hi)(rng));
}

std::uint64_t any64(Rng& rng) { return rng(); }

ErrorCode random_code(Rng& rng) {
  // Includes codes this version does not know: receivers must keep them.
  return static_cast<ErrorCode>(uniform<std::uint16_t>(rng, 1, 40));
}

}  // namespace

const std::vector<MessageType>& all_types() {
  static const std::vector<MessageType> types = {
      MessageType::hello,     MessageType::hello_ack, MessageType::error,
      MessageType::list_maps, MessageType::map_list,  MessageType::open_map,
      MessageType::map_info,  MessageType::get_tiles, MessageType::tile_data,
      MessageType::tile_error, MessageType::cancel,   MessageType::ping,
      MessageType::pong,      MessageType::get_stats, MessageType::stats,
      MessageType::auth,      MessageType::auth_ok};
  return types;
}

std::string random_map_name(Rng& rng) {
  static const std::string first =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789_";
  static const std::string rest = first + ".-";
  const std::size_t n = uniform<std::size_t>(rng, 1, kMaxMapNameBytes);
  std::string s(1, first[uniform<std::size_t>(rng, 0, first.size() - 1)]);
  while (s.size() < n) s += rest[uniform<std::size_t>(rng, 0, rest.size() - 1)];
  return s;
}

std::string random_text(Rng& rng, std::size_t max_bytes) {
  const std::size_t n = uniform<std::size_t>(rng, 0, max_bytes);
  std::string s;
  for (std::size_t i = 0; i < n; ++i) {
    // printable ASCII or a high byte (UTF-8 is not validated), never a control code
    const auto c = uniform<unsigned>(rng, 0x20, 0xff);
    s += static_cast<char>(c == 0x7f ? 'x' : c);
  }
  return s;
}

std::vector<std::uint8_t> random_bytes(Rng& rng, std::size_t max_bytes) {
  std::vector<std::uint8_t> b(uniform<std::size_t>(rng, 0, max_bytes));
  for (auto& x : b) x = static_cast<std::uint8_t>(rng());
  return b;
}

Message random_message(Rng& rng, MessageType type, const Limits& limits) {
  switch (type) {
    case MessageType::hello: {
      Hello m;
      m.min_version = uniform<std::uint8_t>(rng, 1, 200);
      m.max_version = uniform<std::uint8_t>(rng, m.min_version, 255);
      m.max_in_flight = uniform<std::uint16_t>(rng, 1, kMaxInFlightCeiling);
      m.max_frame_bytes = uniform<std::uint32_t>(rng, kMinFrameBytes, kMaxFrameBytesCeiling);
      m.max_tiles_per_batch = uniform<std::uint16_t>(rng, 1, kMaxTilesPerBatchCeiling);
      m.features = static_cast<std::uint32_t>(rng());
      m.client_name = random_text(rng, kMaxLabelBytes);
      return m;
    }
    case MessageType::hello_ack: {
      HelloAck m;
      m.version = uniform<std::uint8_t>(rng, 1, 255);
      m.max_in_flight = uniform<std::uint16_t>(rng, 1, kMaxInFlightCeiling);
      m.max_frame_bytes = uniform<std::uint32_t>(rng, kMinFrameBytes, kMaxFrameBytesCeiling);
      m.max_tiles_per_batch = uniform<std::uint16_t>(rng, 1, kMaxTilesPerBatchCeiling);
      m.features = static_cast<std::uint32_t>(rng());
      for (auto& b : m.nonce) b = static_cast<std::uint8_t>(rng());
      m.server_name = random_text(rng, kMaxLabelBytes);
      return m;
    }
    case MessageType::error:
      return ErrorMessage{random_code(rng), random_text(rng, kMaxErrorMessageBytes)};
    case MessageType::list_maps: return ListMaps{};
    case MessageType::map_list: {
      MapList m;
      std::set<std::string> names;
      const std::size_t n = uniform<std::size_t>(rng, 0, 40);
      while (m.maps.size() < n) {
        MapEntry e;
        e.name = random_map_name(rng);
        if (!names.insert(e.name).second) continue;
        e.encoding = static_cast<std::uint8_t>(rng());
        e.resolution_log2 = uniform<std::uint8_t>(rng, 0, kMaxResolutionLog2);
        e.skip_level = uniform<std::uint8_t>(rng, 0, e.resolution_log2);
        e.tile_count = static_cast<std::uint32_t>(rng());
        e.pack_bytes = any64(rng);
        m.maps.push_back(std::move(e));
      }
      return m;
    }
    case MessageType::open_map: return OpenMap{random_map_name(rng)};
    case MessageType::map_info: {
      MapInfo m;
      m.map_id = uniform<std::uint32_t>(rng, 1, 0xffffffffu);
      m.pack_header = random_bytes(rng, 300);
      m.skip_grid = random_bytes(rng, 3000);
      return m;
    }
    case MessageType::get_tiles: {
      GetTiles m;
      m.map_id = uniform<std::uint32_t>(rng, 1, 0xffffffffu);
      const std::size_t n = uniform<std::size_t>(rng, 1, limits.max_tiles_per_batch);
      std::set<std::uint64_t> ids;
      while (m.tiles.size() < n) {
        // small ids too, so that duplicates are likely and must be skipped
        const std::uint64_t id = (rng() & 1) ? any64(rng) : uniform<std::uint64_t>(rng, 0, 999);
        if (!ids.insert(id).second) continue;
        m.tiles.push_back({id, static_cast<std::uint16_t>(rng())});
      }
      return m;
    }
    case MessageType::tile_data: {
      TileData m;
      m.payload = random_bytes(rng, 5000);
      m.meta.tile_id = any64(rng);
      m.meta.map_id = uniform<std::uint32_t>(rng, 1, 0xffffffffu);
      m.meta.flags = static_cast<std::uint16_t>(rng()) & kKnownTileFlags;
      m.meta.uncompressed_size = (m.meta.flags & kTileFlagZlib)
                                     ? static_cast<std::uint32_t>(rng())
                                     : static_cast<std::uint32_t>(m.payload.size());
      m.meta.payload_crc32 = crc32(m.payload);
      return m;
    }
    case MessageType::tile_error: {
      TileError m;
      m.tile_id = any64(rng);
      m.map_id = uniform<std::uint32_t>(rng, 1, 0xffffffffu);
      m.code = random_code(rng);
      m.message = random_text(rng, 200);
      return m;
    }
    case MessageType::cancel: {
      Cancel m;
      const std::size_t nr = uniform<std::size_t>(rng, 0, limits.max_in_flight);
      for (std::size_t i = 0; i < nr; ++i)
        m.request_ids.push_back(uniform<std::uint32_t>(rng, 1, 0xffffffffu));
      const std::size_t nt = uniform<std::size_t>(rng, nr == 0 ? 1 : 0, 300);
      for (std::size_t i = 0; i < nt; ++i) m.tile_ids.push_back(any64(rng));
      if (nt > 0) m.map_id = uniform<std::uint32_t>(rng, 1, 0xffffffffu);
      return m;
    }
    case MessageType::ping: return Ping{any64(rng)};
    case MessageType::pong: return Pong{any64(rng), any64(rng)};
    case MessageType::get_stats: return GetStats{};
    case MessageType::auth: {
      Auth m;
      for (auto& b : m.client_nonce) b = static_cast<std::uint8_t>(rng());
      for (auto& b : m.proof) b = static_cast<std::uint8_t>(rng());
      return m;
    }
    case MessageType::auth_ok: {
      AuthOk m;
      for (auto& b : m.proof) b = static_cast<std::uint8_t>(rng());
      return m;
    }
    case MessageType::stats: {
      Stats m;
      std::set<std::string> names;
      const std::size_t nc = uniform<std::size_t>(rng, 0, 30);
      while (m.counters.size() < nc) {
        Counter c{random_map_name(rng), any64(rng)};
        if (names.insert(c.name).second) m.counters.push_back(std::move(c));
      }
      names.clear();
      const std::size_t nh = uniform<std::size_t>(rng, 0, 4);
      while (m.histograms.size() < nh) {
        Histogram h{random_map_name(rng), {}};
        if (!names.insert(h.name).second) continue;
        const std::size_t nb = uniform<std::size_t>(rng, 1, kMaxHistogramBuckets);
        std::uint64_t bound = uniform<std::uint64_t>(rng, 0, 100);
        for (std::size_t j = 0; j < nb; ++j) {
          h.buckets.push_back({bound, any64(rng)});
          bound += uniform<std::uint64_t>(rng, 1, 1000);
        }
        m.histograms.push_back(std::move(h));
      }
      return m;
    }
  }
  throw std::logic_error("random_message: unknown type");
}

std::vector<std::uint8_t> random_frame(Rng& rng, const Limits& limits, std::uint32_t request_id,
                                       Message* message) {
  const auto& types = all_types();
  const MessageType t = types[uniform<std::size_t>(rng, 0, types.size() - 1)];
  Message m = random_message(rng, t, limits);
  std::vector<std::uint8_t> out;
  const Status s = encode_message(m, request_id, (rng() & 1) ? kFlagFinal : 0, limits, out);
  if (!s) throw std::logic_error("random_frame: " + to_string(s));
  if (message) *message = std::move(m);
  return out;
}

}  // namespace st::proto::test
