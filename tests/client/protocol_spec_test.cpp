// What proto/PROTOCOL.md promises about the server, checked on the wire (loopback, raw
// sockets, in-process server): the frame cap and the tiles it lets through, index tiles
// marked in TileData, request ids and FINAL on handshake and connection-level Errors,
// Error(timeout) before a timeout closes, what the server accepts silently and what it
// refuses, the Stats names, and how map names come from file names.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <random>
#include <mutex>
#include <thread>

#include "common/error.hpp"
#include "proto/proto.hpp"
#include "server/catalog.hpp"
#include "tests/client/loopback.hpp"
#include "tiles/encode/pack_writer.hpp"
#include "tiles/core/map_preview.hpp"
#include "tiles/core/pack_format.hpp"
#include "tiles/core/tile_cut_grid.hpp"

namespace st::client {
namespace {

using namespace std::chrono_literals;
using looptest::error_code_of;
using looptest::RawFrame;
using looptest::RawSocket;
using looptest::read_frame;
using looptest::start_server;
using proto::ErrorCode;
using proto::MessageType;
using Bytes = std::vector<uint8_t>;

namespace fs = std::filesystem;

fs::path spec_dir() {
  fs::path dir = fs::path(SHADOWTILE_TEST_TMP) / "protocol_spec";
  fs::create_directories(dir);
  return dir;
}

// A pack of 2x2 level-1 cells written directly (the server never decodes tiles, so their
// bytes need not be a real encoding): cell (0, 0) an encoded tile holding `encoded`, cell
// (1, 0) an index tile (a one-level CutGrid of constant children), the rest constant.
struct SyntheticPack {
  std::string path;
  uint64_t encoded_id = 0, index_id = 0;
  Bytes encoded_raw;
};

SyntheticPack write_synthetic_pack(const fs::path& path, Bytes encoded) {
  SyntheticPack out;
  out.path = path.string();
  out.encoded_id = make_tile_id(1, 0, 0);
  out.index_id = make_tile_id(1, 1, 0);
  out.encoded_raw = encoded;
  fs::remove(path);
  fs::remove(out.path + ".tmp");
  CutParams cut;
  cut.map_level = 2;
  cut.skip_level = 1;
  cut.tile_bytes = uint32_t(std::max<size_t>(encoded.size(), 4096));
  PackParams pp = PackParams::from(
      LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), Aabb{{-1, 0, -1}, {1, 1, 1}}), cut);
  pp.compression_level = 1;
  pp.preview_levels = 0;  // its tiles are random bytes: nothing the map preview could decode
  auto w = PackWriter::create(out.path, pp);
  CutGrid grid = CutGrid::constant(1, 0.5f);
  for (uint32_t cy = 0; cy < 2; ++cy)
    for (uint32_t cx = 0; cx < 2; ++cx) {
      CutCell c;
      c.cx = cx;
      c.cy = cy;
      c.entry = GridEntry{0.5f, EntryKind::constant, 0};
      c.lo = c.hi = 0.5f;
      if (cx == 0 && cy == 0) {
        c.entry.kind = EntryKind::tile;
        c.tiles.push_back(CutTile{out.encoded_id, TileKind::encoded, std::move(encoded)});
      } else if (cx == 1 && cy == 0) {
        c.entry = GridEntry{0.5f, EntryKind::index, 1};
        c.tiles.push_back(CutTile{out.index_id, TileKind::index, CutGrid::constant(1, 0.5f).serialize()});
      }
      grid.entry(cx, cy) = c.entry;
      w->append_cell(c);
    }
  w->finish(grid);
  return out;
}

// A pack of level 10 whose skip grid has the most levels a pack allows (K = 10), every
// entry constant and no tiles, written byte by byte (a writer would need all 4^10 cells).
std::string write_deep_grid_pack(const fs::path& path) {
  const uint32_t k = kMaxSkipLevel;
  PackHeader h;
  h.state = PackState::complete;
  h.map_level = h.skip_level = k;
  h.tile_bytes = 4096;
  const LightSpace light =
      LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), Aabb{{-1, 0, -1}, {1, 1, 1}});
  h.light_kind = light.kind();
  h.light = light.to_array();
  const Bytes params = serialize_params({});
  const CutGrid cut_grid = CutGrid::constant(k, 0.5f);
  Bytes grid = cut_grid.serialize();  // then its map preview: no cells (every entry constant)
  const Bytes preview = MapPreview::build(cut_grid, 0, [](uint32_t, uint64_t, uint64_t) { return 0.5f; }).serialize();
  grid.insert(grid.end(), preview.begin(), preview.end());
  h.params_offset = kPackHeaderBytes;
  h.params_size = params.size();
  h.journal_offset = h.params_offset + h.params_size;
  h.grid_offset = (h.journal_offset + 7) & ~uint64_t(7);
  h.grid_size = grid.size();
  h.index_offset = h.grid_offset + h.grid_size;
  h.tile_count = 0;
  h.params_crc = crc32_of(params);
  h.grid_crc = crc32_of(grid);
  h.index_crc = crc32_of({});
  Bytes file(h.index_offset, 0);
  const auto head = h.serialize();
  std::copy(head.begin(), head.end(), file.begin());
  std::copy(params.begin(), params.end(), file.begin() + long(h.params_offset));
  std::copy(grid.begin(), grid.end(), file.begin() + long(h.grid_offset));
  std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(file.data()), long(file.size()));
  return path.string();
}

Bytes random_bytes(size_t n, uint64_t seed) {
  std::mt19937_64 rng(seed);
  Bytes b(n);
  for (auto& x : b) x = uint8_t(rng());
  return b;
}

Bytes frame(const proto::Message& m, uint32_t id, uint8_t flags = proto::kFlagFinal) {
  Bytes out;
  proto::Limits l;
  l.max_frame_bytes = proto::kMaxFrameBytesCeiling;
  l.max_in_flight = proto::kMaxInFlightCeiling;
  l.max_tiles_per_batch = proto::kMaxTilesPerBatchCeiling;
  ST_CHECK(proto::encode_message(m, id, flags, l, out));
  return out;
}

Bytes hello(uint32_t id, uint32_t max_frame_bytes = proto::Limits{}.max_frame_bytes, uint32_t features = 0) {
  proto::Limits l;
  l.max_frame_bytes = max_frame_bytes;
  proto::Hello h = proto::make_hello(l, "spec");
  h.features = features;
  return frame(h, id);
}

template <class T>
T decode(const RawFrame& f) {
  T m;
  proto::Limits big;
  big.max_frame_bytes = proto::kMaxFrameBytesCeiling;
  big.max_in_flight = proto::kMaxInFlightCeiling;
  big.max_tiles_per_batch = proto::kMaxTilesPerBatchCeiling;
  EXPECT_TRUE(proto::decode_payload(f.payload, big, m)) << proto::to_string(f.header.type);
  return m;
}

// Hello -> HelloAck, then OpenMap(name) -> MapInfo; returns the ack (map id in *map_id).
proto::HelloAck open(RawSocket& s, const std::string& name, uint32_t* map_id, uint32_t max_frame_bytes,
                     uint32_t features = 0) {
  EXPECT_TRUE(s.send(hello(1, max_frame_bytes, features)));
  RawFrame ack = read_frame(s);
  EXPECT_EQ(ack.header.type, MessageType::hello_ack);
  EXPECT_TRUE(s.send(frame(proto::OpenMap{name}, 2)));
  RawFrame info = read_frame(s);
  EXPECT_EQ(info.header.type, MessageType::map_info);
  *map_id = decode<proto::MapInfo>(info).map_id;
  return decode<proto::HelloAck>(ack);
}

// Asks for one tile; returns its answer frame.
RawFrame get_tile(RawSocket& s, uint32_t map_id, uint64_t tile, uint32_t request_id = 3) {
  proto::GetTiles g;
  g.map_id = map_id;
  g.tiles = {{tile, 1}};
  EXPECT_TRUE(s.send(frame(g, request_id)));
  return read_frame(s);
}

// ---------------------------------------------------------------- §6 frame cap

// A tile of n stored bytes travels in a frame of n + 52 bytes; the server raises its cap
// to exactly that for the largest tile, and the negotiated cap (the smaller proposal)
// decides, to the byte, whether a tile is served.
TEST(ProtocolSpec, TilesAboveFourMiBAreServedAndTheFrameRuleIsExact) {
  constexpr size_t kRaw = 4'700'000;  // incompressible: stored a little above 4 MiB
  auto pack = write_synthetic_pack(spec_dir() / "big.pack", random_bytes(kRaw, 5));
  auto reader = PackReader::open(pack.path);
  const uint32_t n = reader->find(pack.encoded_id)->stored_size;
  ASSERT_GT(n, 4u << 20);
  const uint32_t need = n + uint32_t(proto::kTileDataPrefixBytes);
  ASSERT_EQ(proto::kTileDataPrefixBytes, 52u);

  std::mutex log_mu;
  std::vector<std::string> log;
  server::ServerOptions so;
  so.log = [&](const std::string& line) {
    std::lock_guard lock(log_mu);
    log.push_back(line);
  };
  auto srv = start_server({pack.path}, so);
  EXPECT_EQ(srv.server->max_frame_bytes(), need);  // raised from 4 MiB, and said so:
  ASSERT_EQ(log.size(), 1u);
  EXPECT_NE(log[0].find("max_frame_bytes raised to " + std::to_string(need)), std::string::npos) << log[0];
  {  // A client proposing the ceiling is granted the server's cap and gets the tile.
    RawSocket s(srv.port);
    uint32_t map = 0;
    EXPECT_EQ(open(s, "big", &map, proto::kMaxFrameBytesCeiling).max_frame_bytes, need);
    RawFrame f = get_tile(s, map, pack.encoded_id);
    ASSERT_EQ(f.header.type, MessageType::tile_data);
    EXPECT_EQ(proto::kHeaderSize + f.header.payload_length, need);
    proto::TileMeta meta;
    std::span<const uint8_t> stored;
    ASSERT_TRUE(proto::decode_tile_data_view(f.payload, meta, stored));
    EXPECT_EQ(stored.size(), n);
    EXPECT_TRUE(proto::tile_crc_matches(meta, stored));
    EXPECT_EQ(zlib_decompress(stored, meta.uncompressed_size, "big"), pack.encoded_raw);
  }
  {  // Proposing exactly n + 52: served.
    RawSocket s(srv.port);
    uint32_t map = 0;
    open(s, "big", &map, need);
    EXPECT_EQ(get_tile(s, map, pack.encoded_id).header.type, MessageType::tile_data);
  }
  {  // One byte less: tile_too_large, for that tile alone.
    RawSocket s(srv.port);
    uint32_t map = 0;
    open(s, "big", &map, need - 1);
    RawFrame f = get_tile(s, map, pack.encoded_id);
    ASSERT_EQ(f.header.type, MessageType::tile_error);
    EXPECT_EQ(decode<proto::TileError>(f).code, ErrorCode::tile_too_large);
    EXPECT_EQ(get_tile(s, map, pack.index_id, 4).header.type, MessageType::tile_data);
  }
  srv.stop();

  // With fit_frame_to_catalog off the cap stays 4 MiB (say, an operator bounding memory):
  // the big tile cannot be served whatever the client proposes, and the log says so.
  log.clear();
  so.fit_frame_to_catalog = false;
  auto fixed = start_server({pack.path}, so);
  EXPECT_EQ(fixed.server->max_frame_bytes(), 4u << 20);
  ASSERT_EQ(log.size(), 1u);
  EXPECT_NE(log[0].find("max_frame_bytes 4194304 is too small for 1 tile(s)"), std::string::npos) << log[0];
  RawSocket s(fixed.port);
  uint32_t map = 0;
  EXPECT_EQ(open(s, "big", &map, proto::kMaxFrameBytesCeiling).max_frame_bytes, 4u << 20);
  RawFrame f = get_tile(s, map, pack.encoded_id);
  ASSERT_EQ(f.header.type, MessageType::tile_error);
  EXPECT_EQ(decode<proto::TileError>(f).code, ErrorCode::tile_too_large);
}

// A skip grid of K = 10 is 9,786,716 bytes: its MapInfo does not fit the default 4 MiB
// frame either, so the server raises its cap for it too; a client proposing less gets
// Error limit_exceeded for that OpenMap and keeps its connection.
TEST(ProtocolSpec, MapInfoOfTheDeepestSkipGridIsServed) {
  const std::string path = write_deep_grid_pack(spec_dir() / "deep.pack");
  const uint64_t grid_bytes = CutGrid::serialized_size(kMaxSkipLevel);
  ASSERT_EQ(grid_bytes, 9'786'716u);
  // The sizes PROTOCOL.md §4.6 and §10 quote.
  EXPECT_EQ(kPackHeaderBytes, 256u);
  EXPECT_EQ(CutGrid::serialized_size(6), 38'236u);
  EXPECT_EQ(CutGrid::serialized_size(8), 611'676u);
  const uint32_t need = uint32_t(proto::kHeaderSize + 12 + kPackHeaderBytes + grid_bytes + kPreviewHeaderBytes);
  auto srv = start_server({path});
  EXPECT_EQ(srv.server->max_frame_bytes(), need);
  {
    RawSocket s(srv.port);
    uint32_t map = 0;
    open(s, "deep", &map, proto::kMaxFrameBytesCeiling);
    EXPECT_EQ(map, 1u);
  }
  {
    RawSocket s(srv.port);
    ASSERT_TRUE(s.send(hello(1, need - 1)));
    ASSERT_EQ(read_frame(s).header.type, MessageType::hello_ack);
    ASSERT_TRUE(s.send(frame(proto::OpenMap{"deep"}, 2)));
    RawFrame e = read_frame(s);
    EXPECT_EQ(e.header.type, MessageType::error);
    EXPECT_EQ(e.header.request_id, 2u);
    EXPECT_TRUE(e.header.final());
    EXPECT_EQ(error_code_of(e), ErrorCode::limit_exceeded);
    ASSERT_TRUE(s.send(frame(proto::Ping{3}, 3)));
    EXPECT_EQ(read_frame(s).header.type, MessageType::pong);
  }
}

// What the server buffers from a client is bounded by the largest message a client may
// send (proto::max_client_frame_bytes), not by the cap raised for tiles; the largest
// legal Cancel still passes.
TEST(ProtocolSpec, ClientFramesAreBoundedByTheLargestClientMessage) {
  auto pack = write_synthetic_pack(spec_dir() / "bound.pack", random_bytes(1000, 6));
  auto srv = start_server({pack.path});
  const proto::Limits negotiated;  // what hello() proposes and the server grants
  const uint32_t bound = proto::max_client_frame_bytes(negotiated);
  ASSERT_LT(bound, negotiated.max_frame_bytes);
  {
    RawSocket s(srv.port);
    ASSERT_TRUE(s.send(hello(1)));
    ASSERT_EQ(read_frame(s).header.type, MessageType::hello_ack);
    proto::Cancel c;  // every request and tile a Cancel may name
    for (uint32_t i = 1; i <= negotiated.max_in_flight; ++i) c.request_ids.push_back(i);
    c.map_id = 1;
    for (uint64_t i = 0; i < uint64_t(negotiated.max_in_flight) * negotiated.max_tiles_per_batch; ++i)
      c.tile_ids.push_back(i);
    Bytes big = frame(c, 0);
    EXPECT_EQ(big.size(), bound);
    ASSERT_TRUE(s.send(big));
    ASSERT_TRUE(s.send(frame(proto::Ping{7}, 9)));
    RawFrame pong = read_frame(s);
    EXPECT_EQ(pong.header.type, MessageType::pong);
    EXPECT_EQ(pong.header.request_id, 9u);
  }
  {  // One byte more than any client message: oversized_frame from the header alone.
    RawSocket s(srv.port);
    ASSERT_TRUE(s.send(hello(1)));
    ASSERT_EQ(read_frame(s).header.type, MessageType::hello_ack);
    proto::FrameHeader h;
    h.type = MessageType::get_tiles;
    h.request_id = 5;
    h.payload_length = bound - uint32_t(proto::kHeaderSize) + 1;
    Bytes bytes(proto::kHeaderSize);
    proto::write_header(h, std::span<uint8_t, proto::kHeaderSize>(bytes.data(), proto::kHeaderSize));
    ASSERT_TRUE(s.send(bytes));
    RawFrame e = read_frame(s);
    EXPECT_EQ(error_code_of(e), ErrorCode::oversized_frame);
    EXPECT_TRUE(s.wait_closed());
  }
}

// ---------------------------------------------------------------- §4.8 tile kind

TEST(ProtocolSpec, TileDataMarksIndexTilesWhenTheClientAsks) {
  auto pack = write_synthetic_pack(spec_dir() / "kinds.pack", random_bytes(2000, 7));
  auto srv = start_server({pack.path});
  for (bool ask : {true, false}) {
    RawSocket s(srv.port);
    uint32_t map = 0;
    const proto::HelloAck ack =
        open(s, "kinds", &map, proto::Limits{}.max_frame_bytes, ask ? proto::kFeatureTileKind : 0);
    EXPECT_EQ(ack.features, ask ? proto::kFeatureTileKind : 0u);
    proto::TileMeta meta;
    std::span<const uint8_t> stored;
    RawFrame e = get_tile(s, map, pack.encoded_id, 3);
    ASSERT_TRUE(proto::decode_tile_data_view(e.payload, meta, stored));
    EXPECT_EQ(meta.flags, proto::kTileFlagZlib);
    RawFrame i = get_tile(s, map, pack.index_id, 4);
    ASSERT_TRUE(proto::decode_tile_data_view(i.payload, meta, stored));
    EXPECT_EQ(meta.flags, ask ? (proto::kTileFlagZlib | proto::kTileFlagIndex) : proto::kTileFlagZlib);
    // The index tile inflates to a CutGrid (tiles/PACK.md), whatever the flag says.
    EXPECT_NO_THROW(CutGrid::parse(zlib_decompress(stored, meta.uncompressed_size, "index"), "index", 4));
  }
}

// ---------------------------------------------------------------- §2, §5 handshake errors

TEST(ProtocolSpec, HandshakeAndConnectionErrorsCarryRequestIdZeroAndFinal) {
  auto pack = write_synthetic_pack(spec_dir() / "hs.pack", random_bytes(1000, 8));
  auto srv = start_server({pack.path});
  auto expect_closing_error = [](RawSocket& s, ErrorCode code) {
    RawFrame e = read_frame(s);
    ASSERT_TRUE(e.ok);
    EXPECT_EQ(e.header.type, MessageType::error);
    EXPECT_EQ(e.header.request_id, 0u);
    EXPECT_TRUE(e.header.final());
    EXPECT_EQ(error_code_of(e), code);
    EXPECT_TRUE(s.wait_closed());
  };
  {  // No common version: the Hello's id (1) is not echoed.
    RawSocket s(srv.port);
    proto::Hello h = proto::make_hello(proto::Limits{}, "future", 2, 3);
    ASSERT_TRUE(s.send(frame(h, 1)));
    expect_closing_error(s, ErrorCode::unsupported_version);
  }
  {  // A Hello with request id 0 is refused.
    RawSocket s(srv.port);
    ASSERT_TRUE(s.send(hello(0)));
    expect_closing_error(s, ErrorCode::invalid_field);
  }
  {  // A request before the Hello.
    RawSocket s(srv.port);
    ASSERT_TRUE(s.send(frame(proto::ListMaps{}, 4)));
    expect_closing_error(s, ErrorCode::handshake_required);
  }
  {  // After the handshake, a framing error: the same shape.
    RawSocket s(srv.port);
    ASSERT_TRUE(s.send(hello(1)));
    ASSERT_EQ(read_frame(s).header.type, MessageType::hello_ack);
    ASSERT_TRUE(s.send(Bytes(30, 'X')));
    expect_closing_error(s, ErrorCode::bad_magic);
  }
}

// ---------------------------------------------------------------- §4.11 timeouts

TEST(ProtocolSpec, TimeoutsSendErrorTimeoutBeforeClosing) {
  auto pack = write_synthetic_pack(spec_dir() / "timeouts.pack", random_bytes(1000, 9));
  server::ServerOptions so;
  so.handshake_timeout = so.idle_timeout = so.read_timeout = 300ms;
  auto srv = start_server({pack.path}, so);
  auto expect_timeout = [](RawSocket& s, std::chrono::steady_clock::time_point since, const char* what) {
    RawFrame e = read_frame(s);
    const auto waited = std::chrono::steady_clock::now() - since;
    ASSERT_TRUE(e.ok) << what;
    EXPECT_EQ(e.header.type, MessageType::error) << what;
    EXPECT_EQ(e.header.request_id, 0u) << what;
    EXPECT_TRUE(e.header.final()) << what;
    EXPECT_EQ(error_code_of(e), ErrorCode::timeout) << what;
    EXPECT_NE(decode<proto::ErrorMessage>(e).message.find(what), std::string::npos) << what;
    EXPECT_GE(waited, 300ms) << what;
    EXPECT_LT(waited, 4s) << what;
    EXPECT_TRUE(s.wait_closed()) << what;
  };
  // Each clock starts before the event that starts the server's timer (the connect, the Hello),
  // never after its answer: the server may arm its timer before our read returns.
  {  // Connected, never says Hello.
    const auto t0 = std::chrono::steady_clock::now();
    RawSocket s(srv.port);
    expect_timeout(s, t0, "handshake");
  }
  {  // Handshaken, then silent with nothing owed.
    RawSocket s(srv.port);
    const auto t0 = std::chrono::steady_clock::now();
    ASSERT_TRUE(s.send(hello(1)));
    ASSERT_EQ(read_frame(s).header.type, MessageType::hello_ack);
    expect_timeout(s, t0, "idle");
  }
  {  // Half a frame, then nothing: the read timeout counts from the frame's first byte.
    RawSocket s(srv.port);
    ASSERT_TRUE(s.send(hello(1)));
    ASSERT_EQ(read_frame(s).header.type, MessageType::hello_ack);
    Bytes half = frame(proto::ListMaps{}, 2);
    half.resize(10);
    const auto t0 = std::chrono::steady_clock::now();
    ASSERT_TRUE(s.send(half));
    expect_timeout(s, t0, "read");
  }
  {  // A client that pings keeps an otherwise idle connection open past the idle timeout.
    RawSocket s(srv.port);
    ASSERT_TRUE(s.send(hello(1)));
    ASSERT_EQ(read_frame(s).header.type, MessageType::hello_ack);
    for (uint32_t i = 0; i < 6; ++i) {
      std::this_thread::sleep_for(100ms);
      ASSERT_TRUE(s.send(frame(proto::Ping{i}, 10 + i)));
      RawFrame pong = read_frame(s);
      ASSERT_EQ(pong.header.type, MessageType::pong) << i;
      EXPECT_EQ(pong.header.request_id, 10 + i);
    }
  }
  // Handshake and read timeouts count in `timeouts`; an idle close does not.
  EXPECT_TRUE(looptest::wait_until([&] { return srv.server->stats().connections_open == 0; }, 5s));
  EXPECT_EQ(srv.server->stats().timeouts, 2u);
}

// ---------------------------------------------------------------- §2, §4.10, §7.3 leniency

TEST(ProtocolSpec, FinalOnRequestsIsIgnoredAndCancelNeverAnswers) {
  auto pack = write_synthetic_pack(spec_dir() / "lenient.pack", random_bytes(1000, 10));
  auto srv = start_server({pack.path});
  {
    RawSocket s(srv.port);
    uint32_t map = 0;
    open(s, "lenient", &map, proto::Limits{}.max_frame_bytes);
    for (uint8_t flags : {uint8_t(0), proto::kFlagFinal}) {  // a request with or without FINAL
      ASSERT_TRUE(s.send(frame(proto::ListMaps{}, 5u + flags, flags)));
      RawFrame list = read_frame(s);
      EXPECT_EQ(list.header.type, MessageType::map_list);
      EXPECT_EQ(list.header.request_id, 5u + flags);
      EXPECT_TRUE(list.header.final());
    }
    // Cancel naming requests never sent, and tiles of a map id never opened: ignored, no
    // answer; the next frame is the Pong.
    proto::Cancel c;
    c.request_ids = {77, 78};
    ASSERT_TRUE(s.send(frame(c, 0, 0)));
    c.request_ids.clear();
    c.map_id = 99;
    c.tile_ids = {pack.encoded_id};
    ASSERT_TRUE(s.send(frame(c, 0, proto::kFlagFinal)));
    ASSERT_TRUE(s.send(frame(proto::Ping{1}, 7, 0)));
    RawFrame pong = read_frame(s);
    EXPECT_EQ(pong.header.type, MessageType::pong);
    EXPECT_EQ(pong.header.request_id, 7u);
    EXPECT_TRUE(pong.header.final());
    // A Pong the server never asked for is ignored too.
    ASSERT_TRUE(s.send(frame(proto::Pong{1, 2}, 0, 0)));
    EXPECT_EQ(get_tile(s, map, pack.encoded_id).header.type, MessageType::tile_data);
  }
  {  // A Cancel with a request id is refused: it is no request and gets no answer.
    RawSocket s(srv.port);
    ASSERT_TRUE(s.send(hello(1)));
    ASSERT_EQ(read_frame(s).header.type, MessageType::hello_ack);
    proto::Cancel c;
    c.request_ids = {3};
    ASSERT_TRUE(s.send(frame(c, 3)));
    RawFrame e = read_frame(s);
    EXPECT_EQ(e.header.request_id, 0u);
    EXPECT_EQ(error_code_of(e), ErrorCode::invalid_field);
    EXPECT_TRUE(s.wait_closed());
  }
}

// ---------------------------------------------------------------- §4.12 Stats

// The counters PROTOCOL.md §4.12 lists, by name and in this order, and the histogram's
// bucket bounds.
TEST(ProtocolSpec, StatsNamesAreTheDocumentedOnes) {
  auto pack = write_synthetic_pack(spec_dir() / "stats.pack", random_bytes(1000, 11));
  auto srv = start_server({pack.path});
  RawSocket s(srv.port);
  uint32_t map = 0;
  open(s, "stats", &map, proto::Limits{}.max_frame_bytes);
  ASSERT_EQ(get_tile(s, map, pack.encoded_id).header.type, MessageType::tile_data);
  ASSERT_TRUE(s.send(frame(proto::GetStats{}, 8)));
  RawFrame f = read_frame(s);
  ASSERT_EQ(f.header.type, MessageType::stats);
  const proto::Stats st = decode<proto::Stats>(f);
  std::vector<std::string> names;
  for (const auto& c : st.counters) names.push_back(c.name);
  const std::vector<std::string> documented = {
      "connections_total", "connections_open", "connections_rejected", "requests",
      "tiles_sent",        "tile_bytes_sent",  "bytes_sent",           "bytes_received",
      "tiles_cancelled",   "errors",           "protocol_errors",      "timeouts",
      "latency_p50_us",    "latency_p99_us",   "auth_failures",        "tiles_corrupt",
      "connections_evicted", "log_lines_suppressed", "latency_sum_us"};
  EXPECT_EQ(names, documented);
  auto counter = [&](const std::string& name) {
    for (const auto& c : st.counters)
      if (c.name == name) return c.value;
    return ~uint64_t(0);
  };
  EXPECT_EQ(counter("connections_open"), 1u);
  EXPECT_EQ(counter("tiles_sent"), 1u);
  EXPECT_EQ(counter("requests"), 3u);  // OpenMap, GetTiles, GetStats (not the Hello)
  ASSERT_EQ(st.histograms.size(), 1u);
  EXPECT_EQ(st.histograms[0].name, "latency_us");
  ASSERT_EQ(st.histograms[0].buckets.size(), 32u);
  uint64_t samples = 0;
  for (uint32_t b = 0; b < 32; ++b) {
    EXPECT_EQ(st.histograms[0].buckets[b].upper_bound, b == 31 ? ~uint64_t(0) : (uint64_t(1) << b) - 1);
    samples += st.histograms[0].buckets[b].count;
  }
  EXPECT_EQ(samples, 1u);
}

// ---------------------------------------------------------------- map names

TEST(ProtocolSpec, MapNamesComeFromFileNames) {
  const fs::path dir = spec_dir() / "names";
  fs::remove_all(dir);
  fs::create_directories(dir / "sub");
  const Bytes tile = random_bytes(500, 12);
  write_synthetic_pack(dir / "Alpha.pack", tile);
  write_synthetic_pack(dir / "beta.v2.pack", tile);
  write_synthetic_pack(dir / "-dash.pack", tile);       // breaks the name rules: skipped
  write_synthetic_pack(dir / "sub" / "deep.pack", tile);  // not recursive
  fs::copy_file(dir / "Alpha.pack", dir / "gamma.pack.tmp");
  fs::copy_file(dir / "Alpha.pack", dir / "plain.bin");  // not *.pack: skipped in a directory
  std::vector<std::string> warnings;
  auto c = server::Catalog::scan(std::vector<std::string>{dir.string()},
                                 [&](const std::string& w) { warnings.push_back(w); });
  std::vector<std::string> names;
  for (const auto& m : c.maps()) names.push_back(m->name());
  EXPECT_EQ(names, (std::vector<std::string>{"Alpha", "beta.v2"}));  // byte order, case kept
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_NE(warnings[0].find("-dash.pack"), std::string::npos);
  // Named on the command line: ".pack" is dropped, any other file name is kept whole.
  auto named = server::Catalog::scan(std::vector<std::string>{(dir / "plain.bin").string(), (dir / "sub" / "deep.pack").string()});
  names.clear();
  for (const auto& m : named.maps()) names.push_back(m->name());
  EXPECT_EQ(names, (std::vector<std::string>{"deep", "plain.bin"}));
  EXPECT_THROW(server::Catalog::scan(std::vector<std::string>{(dir / "-dash.pack").string()}), Error);
}

}  // namespace
}  // namespace st::client
