// Loopback throughput of the tile server and the client library, side by side with the
// local pack read (same tiles, same machine, one run):
//   local      PackReader::read_raw + open_encoded of every tile (no network)
//   raw N      N raw connections pipelining GetTiles (64 in flight x 8 tiles), frames
//              read and dropped: what the server alone sustains
//   client N   N st::client::Client each fetching the whole map into its cache
//              (CRC check, zlib, tile validation included)
// Prints a table (medians of --reps runs) and writes JSON (--json PATH).
//   bench_serve_loopback [--level 10] [--reps 3] [--json bench-out/serve_loopback.json]
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <arpa/inet.h>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "bench/options.hpp"
#include "client/map_access.hpp"
#include "proto/proto.hpp"
#include "server/server.hpp"
#include "common/error.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/core/pack_reader.hpp"
#include "tiles/encode/pack_writer.hpp"

using namespace st;
using Clock = std::chrono::steady_clock;

namespace {

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// Noisy blocks between smooth ones: tiles of a few KiB, like a city's detailed cells.
IntervalTile bench_field(uint32_t level) {
  const uint32_t side = 1u << level;
  IntervalTile t;
  t.level = level;
  t.width = t.height = side;
  t.data.resize(size_t(side) * side);
  uint64_t s = 12345;
  auto next = [&] {
    s = s * 6364136223846793005ull + 1442695040888963407ull;
    return uint32_t(s >> 40);
  };
  for (uint32_t y = 0; y < side; ++y)
    for (uint32_t x = 0; x < side; ++x) {
      const bool noisy = ((x / 16) + (y / 16)) % 3 == 0;
      float d = noisy ? float(next() % 1000) / 1000.0f : 0.3f + 0.0004f * float(x % 64) + 0.0002f * float(y % 64);
      t.at(x, y) = {d, noisy ? d + 0.01f : d};
    }
  return t;
}

// A raw client: pipelines GetTiles for all tiles of map 1, drops the answers.
double raw_fetch_all(uint16_t port, const std::vector<uint64_t>& ids) {
  int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  int one = 1;
  ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port);
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) throw Error("connect failed");
  proto::Limits hl;
  hl.max_frame_bytes = proto::kMinFrameBytes;
  proto::Limits l;
  std::vector<uint8_t> out;
  (void)proto::encode_message(proto::make_hello(l, "bench"), 1, proto::kFlagFinal, hl, out);
  (void)proto::encode_message(proto::OpenMap{"bench"}, 2, proto::kFlagFinal, l, out);
  ::send(fd, out.data(), out.size(), 0);
  proto::FrameParser parser(hl, proto::Receiver::client);
  std::vector<uint8_t> buf(1 << 20);
  size_t next_tile = 0, done_tiles = 0, in_flight = 0;
  uint32_t next_id = 3;
  bool ready = false;
  const auto t0 = Clock::now();
  while (done_tiles < ids.size()) {
    out.clear();
    while (ready && in_flight < 64 && next_tile < ids.size()) {
      proto::GetTiles g;
      g.map_id = 1;
      for (size_t k = 0; k < 8 && next_tile < ids.size(); ++k) g.tiles.push_back({ids[next_tile++], 0});
      (void)proto::encode_message(g, next_id++, proto::kFlagFinal, l, out);
      ++in_flight;
    }
    if (!out.empty()) ::send(fd, out.data(), out.size(), 0);
    ssize_t n = ::recv(fd, buf.data(), buf.size(), 0);
    if (n <= 0) throw Error("raw client: connection closed");
    std::span<const uint8_t> rest(buf.data(), size_t(n));
    while (!rest.empty()) {
      auto r = parser.feed(rest);
      rest = rest.subspan(r.consumed);
      if (r.state == proto::FrameParser::State::error) throw Error("raw client: " + proto::to_string(parser.status()));
      if (r.state != proto::FrameParser::State::frame) break;
      proto::Frame f = parser.take_frame();
      if (f.header.type == proto::MessageType::hello_ack) {
        parser.set_limits(l);
      } else if (f.header.type == proto::MessageType::map_info) {
        ready = true;
      } else if (f.header.type == proto::MessageType::tile_data || f.header.type == proto::MessageType::tile_error) {
        ++done_tiles;
        if (f.header.final()) --in_flight;
      }
    }
  }
  const double s = seconds_since(t0);
  ::close(fd);
  return s;
}

}  // namespace

int main(int argc, char** argv) {
  uint32_t level = 10, reps = 3;
  std::string json_path = "bench-out/serve_loopback.json";
  st::bench::Options opt("bench_serve_loopback", "Loopback throughput of the tile server and the client beside the local pack read");
  opt.value("--level", level, "Map level (side 2^level)")
      .value("--reps", reps, "Median of R runs")
      .value("--json", json_path, "Write the rows as JSON to PATH");
  opt.parse(argc, argv);
  try {
    namespace fs = std::filesystem;
    fs::path dir = fs::temp_directory_path() / "shadowtile_bench_serve";
    fs::create_directories(dir);
    const std::string pack = (dir / "bench.pack").string();
    CutParams cut;
    cut.map_level = level;
    cut.skip_level = std::min<uint32_t>(level - 4, 8);
    cut.codec = TileCodec::of(Encoding::mh);
    LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), Aabb{{-1, 0, -1}, {1, 1, 1}});
    fs::remove(pack);
    write_pack(pack, build_hierarchy(bench_field(level)), cut, PackParams::from(light, cut));
    auto reader = std::shared_ptr<PackReader>(PackReader::open(pack));
    std::vector<uint64_t> ids;
    uint64_t stored = 0;
    for (auto& t : reader->tiles()) ids.push_back(t.id), stored += t.stored_size;
    const double tiles = double(ids.size()), mb = double(stored) / 1e6;
    std::printf("pack: level %u, K %u, %zu tiles, %.2f MB stored (%.0f B/tile)\n", level, cut.skip_level,
                ids.size(), mb, double(stored) / tiles);

    nlohmann::json rows = nlohmann::json::array();
    std::printf("%-12s %12s %10s %10s\n", "run", "tiles/s", "MB/s", "x local");
    double local_rate = 0;
    auto row = [&](const std::string& name, double secs, double mult) {
      double rate = tiles * mult / secs;
      if (local_rate == 0) local_rate = rate;
      std::printf("%-12s %12.0f %10.1f %10.2f\n", name.c_str(), rate, mb * mult / secs, rate / local_rate);
      rows.push_back({{"run", name}, {"tiles_per_s", rate}, {"mb_per_s", mb * mult / secs},
                      {"ratio_vs_local", rate / local_rate}, {"median_seconds", secs}});
    };
    {
      std::vector<double> t;
      for (uint32_t r = 0; r < reps; ++r) {
        auto t0 = Clock::now();
        for (uint64_t id : ids) {
          auto raw = reader->read_raw(id);
          auto ev = open_encoded(Encoding::mh, raw);
        }
        t.push_back(seconds_since(t0));
      }
      row("local", median(t), 1);
    }
    server::ServerOptions so;
    so.port = 0;
    so.log = [](const std::string&) {};
    server::Server srv(server::Catalog::scan(std::vector<std::string>{pack}), so);
    srv.start();
    for (int n : {1, 4, 8}) {
      std::vector<double> t;
      for (uint32_t r = 0; r < reps; ++r) {
        auto t0 = Clock::now();
        std::vector<std::thread> th;
        for (int c = 0; c < n; ++c) th.emplace_back([&] { raw_fetch_all(srv.port(), ids); });
        for (auto& x : th) x.join();
        t.push_back(seconds_since(t0));
      }
      row("raw " + std::to_string(n), median(t), n);
    }
    for (int n : {1, 4}) {
      std::vector<double> t;
      for (uint32_t r = 0; r < reps; ++r) {
        client::ClientOptions co;
        co.cache_slots = uint32_t(ids.size());
        std::vector<std::unique_ptr<client::Client>> clients;
        std::vector<client::Map> maps;
        for (int c = 0; c < n; ++c) {
          clients.push_back(std::make_unique<client::Client>(client::Endpoint{"127.0.0.1", srv.port()}, co));
          maps.push_back(clients.back()->open("bench"));
        }
        const uint64_t side = uint64_t(1) << level;
        auto t0 = Clock::now();
        for (auto& m : maps) m.request_region(level, 0, 0, side, side, 1);
        // Poll the cheap counter (region_resident walks every cell under the map's lock).
        for (auto& m : maps)
          while (m.stats().tiles_received < ids.size()) std::this_thread::sleep_for(std::chrono::microseconds(500));
        t.push_back(seconds_since(t0));
        for (auto& m : maps)
          if (!m.region_resident(level, 0, 0, side, side)) throw Error("client: map not fully resident");
      }
      row("client " + std::to_string(n), median(t), n);
    }
    srv.stop();
    std::printf("server: %s\n", srv.stats().line().c_str());
    fs::create_directories(fs::path(json_path).parent_path().empty() ? "." : fs::path(json_path).parent_path());
    nlohmann::json j = {{"benchmark", "serve_loopback"}, {"level", level}, {"tiles", ids.size()},
                        {"stored_bytes", stored}, {"reps", reps}, {"rows", rows}};
    std::ofstream(json_path) << j.dump(2) << "\n";
    std::printf("wrote %s\n", json_path.c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_serve_loopback: %s\n", e.what());
    return 1;
  }
  return 0;
}
