// Our tile server against nginx serving the same stored tile bytes as static files, under
// the same load in the same run (everything on 127.0.0.1):
//   ours        shadowtile::server (1 I/O thread, the default) speaking our protocol:
//               GetTiles of one tile per request, TileData answers
//   nginx wN    nginx 1.22 child process (daemon off, master_process off, N workers,
//               sendfile, keep-alive) serving one file per tile exported with
//               PackReader::read_stored: `GET /tiles/<id> HTTP/1.1`, Content-Length bodies
// One load driver for both: one blocking thread per connection keeps --depth requests in
// flight (pipelined) for --seconds, random tile ids (same seed per connection for every
// server), latency from the send of a request to the full receipt of its answer.
// Bytes counted are tile bytes (the stored blob) on both sides, not framing or headers.
// Prints a table (connections x server: tiles/s, MB/s, p50/p99/p99.9 ms, ratio ours/nginx)
// and writes JSON. Without nginx on PATH (or --nginx) it says so and measures ours only.
//   bench_serve_vs_nginx [--level 10] [--seconds 3] [--warmup 0.3] [--depth 8]
//                        [--conns 1,8,64] [--nginx-workers 1,auto] [--nginx PATH] [--skip K]
//                        [--nginx-extra "open_file_cache max=65536 inactive=60s;"]
//                        [--json bench-out/serve_vs_nginx.json] [--threads T (our I/O threads)]
#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "proto/proto.hpp"
#include "server/server.hpp"
#include "common/error.hpp"
#include "tiles/build/mh_build.hpp"
#include "tiles/core/pack_reader.hpp"
#include "tiles/build/pack_writer.hpp"

using namespace st;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

double since(Clock::time_point t0, Clock::time_point t1) { return std::chrono::duration<double>(t1 - t0).count(); }

// Noisy blocks between smooth ones: tiles of a few KiB (the field bench_serve_loopback uses).
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

int connect_loopback(uint16_t port) {
  int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) throw Error("socket() failed");
  int one = 1;
  ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
  // A stalled server must not hang the benchmark: recv gives up after 5 s.
  timeval tv{5, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port);
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
    ::close(fd);
    throw Error("connect to 127.0.0.1:" + std::to_string(port) + " failed");
  }
  return fd;
}

void send_all(int fd, const void* data, size_t n) {
  auto* p = static_cast<const uint8_t*>(data);
  while (n > 0) {
    ssize_t k = ::send(fd, p, n, MSG_NOSIGNAL);
    if (k <= 0) throw Error("send failed: " + std::string(std::strerror(errno)));
    p += k, n -= size_t(k);
  }
}

size_t recv_some(int fd, std::vector<uint8_t>& buf, const char* who) {
  ssize_t n = ::recv(fd, buf.data(), buf.size(), 0);
  if (n == 0) throw Error(std::string(who) + ": connection closed by server");
  if (n < 0) throw Error(std::string(who) + ": recv failed: " + std::strerror(errno));
  return size_t(n);
}

// What one connection measured inside the window [start, stop).
struct ConnResult {
  uint64_t tiles = 0, bytes = 0;
  std::vector<double> latency_s;
  std::string error;
};

struct Window {
  Clock::time_point start, stop;
  bool counts(Clock::time_point t) const { return t >= start && t < stop; }
};

// Our protocol: Hello, OpenMap, then GetTiles of one tile each, `depth` in flight.
void run_ours(uint16_t port, const std::vector<uint64_t>& ids, uint32_t depth, uint32_t seed, Window w,
              ConnResult& res) {
  int fd = connect_loopback(port);
  try {
    proto::Limits hl;
    hl.max_frame_bytes = proto::kMinFrameBytes;
    proto::Limits l;
    std::vector<uint8_t> out;
    (void)proto::encode_message(proto::make_hello(l, "bench_serve_vs_nginx"), 1, proto::kFlagFinal, hl, out);
    (void)proto::encode_message(proto::OpenMap{"bench"}, 2, proto::kFlagFinal, l, out);
    send_all(fd, out.data(), out.size());
    proto::FrameParser parser(hl, proto::Receiver::client);
    std::vector<uint8_t> buf(1 << 18);
    std::mt19937_64 rng(seed);
    std::vector<Clock::time_point> sent(1024);  // by request id % 1024 (depth <= 64 in flight)
    uint32_t next_id = 3, in_flight = 0;
    bool ready = false;
    for (;;) {
      const auto now = Clock::now();
      if (now >= w.stop) break;
      out.clear();
      while (ready && in_flight < depth) {
        proto::GetTiles g;
        g.map_id = 1;
        g.tiles.push_back({ids[rng() % ids.size()], 0});
        (void)proto::encode_message(g, next_id, proto::kFlagFinal, l, out);
        sent[next_id % sent.size()] = now;
        ++next_id, ++in_flight;
      }
      if (!out.empty()) send_all(fd, out.data(), out.size());
      std::span<const uint8_t> rest(buf.data(), recv_some(fd, buf, "ours"));
      while (!rest.empty()) {
        auto r = parser.feed(rest);
        rest = rest.subspan(r.consumed);
        if (r.state == proto::FrameParser::State::error) throw Error("ours: " + proto::to_string(parser.status()));
        if (r.state != proto::FrameParser::State::frame) break;
        proto::Frame f = parser.take_frame();
        const auto t = Clock::now();
        switch (f.header.type) {
          case proto::MessageType::hello_ack: parser.set_limits(l); break;
          case proto::MessageType::map_info: ready = true; break;
          case proto::MessageType::tile_data:
            if (w.counts(t)) {
              ++res.tiles;
              res.bytes += f.payload.size() - std::min<size_t>(f.payload.size(), 28);  // TileMeta: 28 B
              res.latency_s.push_back(since(sent[f.header.request_id % sent.size()], t));
            }
            if (f.header.final()) --in_flight;
            break;
          case proto::MessageType::tile_error: throw Error("ours: TileError for a listed tile");
          case proto::MessageType::error: throw Error("ours: server sent Error");
          default: break;
        }
      }
    }
  } catch (...) {
    ::close(fd);
    throw;
  }
  ::close(fd);
}

// HTTP/1.1 keep-alive with pipelining: answers come back in request order, so send times
// queue up FIFO. Parses the status line and Content-Length; skips the body.
void run_http(uint16_t port, const std::vector<uint64_t>& ids, uint32_t depth, uint32_t seed, Window w,
              ConnResult& res) {
  int fd = connect_loopback(port);
  try {
    std::vector<uint8_t> buf(1 << 18);
    std::string pending;  // unparsed header bytes
    std::deque<Clock::time_point> sent;
    std::mt19937_64 rng(seed);
    uint64_t body_left = 0, body_size = 0;
    bool in_body = false;
    std::string out;
    auto finish = [&](Clock::time_point t) {
      if (w.counts(t)) {
        ++res.tiles;
        res.bytes += body_size;
        res.latency_s.push_back(since(sent.front(), t));
      }
      sent.pop_front();
      in_body = false;
    };
    for (;;) {
      const auto now = Clock::now();
      if (now >= w.stop) break;
      out.clear();
      while (sent.size() < depth) {
        out += "GET /tiles/" + std::to_string(ids[rng() % ids.size()]) + " HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n";
        sent.push_back(now);
      }
      if (!out.empty()) send_all(fd, out.data(), out.size());
      const size_t n = recv_some(fd, buf, "nginx");
      size_t pos = 0;
      while (pos < n) {
        if (in_body) {
          const size_t take = size_t(std::min<uint64_t>(body_left, n - pos));
          pos += take, body_left -= take;
          if (body_left == 0) finish(Clock::now());
          continue;
        }
        // Header bytes: append until the blank line (headers are ~200 B, no quadratic cost).
        const size_t old = pending.size();
        pending.append(reinterpret_cast<const char*>(buf.data()) + pos, n - pos);
        const size_t end = pending.find("\r\n\r\n", old >= 3 ? old - 3 : 0);
        if (end == std::string::npos) {
          pos = n;
          if (pending.size() > 16384) throw Error("nginx: response header over 16 KiB");
          break;
        }
        const std::string head = pending.substr(0, end);
        pos += end + 4 - old;
        pending.clear();
        if (head.rfind("HTTP/1.1 200", 0) != 0) throw Error("nginx: " + head.substr(0, head.find('\r')));
        std::string lower = head;
        std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return std::tolower(c); });
        const size_t cl = lower.find("\r\ncontent-length:");
        if (cl == std::string::npos) throw Error("nginx: response without Content-Length");
        body_size = body_left = std::stoull(lower.substr(cl + 17));
        in_body = true;
        if (body_left == 0) finish(Clock::now());
      }
    }
  } catch (...) {
    ::close(fd);
    throw;
  }
  ::close(fd);
}

struct Cell {
  std::string server;
  int conns = 0;
  double tiles_per_s = 0, mb_per_s = 0, p50_ms = 0, p99_ms = 0, p999_ms = 0;
  uint64_t tiles = 0;
};

double pct(const std::vector<double>& sorted, double p) {
  if (sorted.empty()) return 0;
  size_t i = size_t(p * double(sorted.size() - 1) + 0.5);
  return sorted[std::min(i, sorted.size() - 1)];
}

using Driver = void (*)(uint16_t, const std::vector<uint64_t>&, uint32_t, uint32_t, Window, ConnResult&);

Cell measure(const std::string& server, Driver drive, uint16_t port, const std::vector<uint64_t>& ids, int conns,
             uint32_t depth, double warmup_s, double seconds) {
  const auto t0 = Clock::now() + std::chrono::milliseconds(50);  // time for every thread to connect
  Window w;
  w.start = t0 + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(warmup_s));
  w.stop = w.start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds));
  std::vector<ConnResult> res(static_cast<size_t>(conns));
  std::vector<std::thread> th;
  for (int c = 0; c < conns; ++c)
    th.emplace_back([&, c] {
      try {
        drive(port, ids, depth, 1000u + uint32_t(c), w, res[size_t(c)]);
      } catch (const std::exception& e) {
        res[size_t(c)].error = e.what();
      }
    });
  for (auto& t : th) t.join();
  Cell cell;
  cell.server = server;
  cell.conns = conns;
  std::vector<double> lat;
  uint64_t bytes = 0;
  for (auto& r : res) {
    if (!r.error.empty()) throw Error(server + " with " + std::to_string(conns) + " connections: " + r.error);
    cell.tiles += r.tiles;
    bytes += r.bytes;
    lat.insert(lat.end(), r.latency_s.begin(), r.latency_s.end());
  }
  std::sort(lat.begin(), lat.end());
  cell.tiles_per_s = double(cell.tiles) / seconds;
  cell.mb_per_s = double(bytes) / 1e6 / seconds;
  cell.p50_ms = pct(lat, 0.5) * 1e3;
  cell.p99_ms = pct(lat, 0.99) * 1e3;
  cell.p999_ms = pct(lat, 0.999) * 1e3;
  return cell;
}

// ---- nginx as a child process ----

std::optional<std::string> find_nginx(const std::string& explicit_path) {
  if (!explicit_path.empty()) return fs::exists(explicit_path) ? std::optional(explicit_path) : std::nullopt;
  std::string path = getenv("PATH") ? getenv("PATH") : "";
  path += ":/usr/sbin:/usr/local/sbin:/usr/local/nginx/sbin";
  std::stringstream ss(path);
  for (std::string d; std::getline(ss, d, ':');)
    if (!d.empty() && ::access((fs::path(d) / "nginx").c_str(), X_OK) == 0) return (fs::path(d) / "nginx").string();
  return std::nullopt;
}

uint16_t free_port() {
  int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof a;
  if (::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 ||
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) != 0) {
    ::close(fd);
    throw Error("could not find a free port on 127.0.0.1");
  }
  ::close(fd);
  return ntohs(a.sin_port);
}

class Nginx {
 public:
  Nginx(const std::string& binary, const fs::path& dir, const fs::path& www, const std::string& workers,
        const std::string& extra)
      : dir_(dir) {
    fs::create_directories(dir / "tmp");
    port_ = free_port();
    const std::string d = dir.string();
    std::ofstream conf(dir / "nginx.conf");
    conf << "daemon off;\nmaster_process off;\nworker_processes " << workers << ";\n"
         << "pid " << d << "/nginx.pid;\nerror_log " << d << "/error.log warn;\n"
         << "events { worker_connections 1024; }\n"
         << "http {\n  access_log off;\n  sendfile on;\n  tcp_nopush off;\n  tcp_nodelay on;\n"
         << "  keepalive_requests 1000000;\n  keepalive_timeout 120s;\n"
         << "  default_type application/octet-stream;\n  " << extra << "\n"
         << "  client_body_temp_path " << d << "/tmp/body;\n  proxy_temp_path " << d << "/tmp/proxy;\n"
         << "  fastcgi_temp_path " << d << "/tmp/fastcgi;\n  uwsgi_temp_path " << d << "/tmp/uwsgi;\n"
         << "  scgi_temp_path " << d << "/tmp/scgi;\n"
         << "  server {\n    listen 127.0.0.1:" << port_ << ";\n    root " << www.string() << ";\n"
         << "    location /tiles/ { }\n  }\n}\n";
    conf.close();
    const std::string conf_path = (dir / "nginx.conf").string(), err_path = (dir / "error.log").string();
    pid_ = ::fork();
    if (pid_ < 0) throw Error("fork failed");
    if (pid_ == 0) {
      // -p/-e keep nginx off /var/log/nginx before it reads the config.
      ::execl(binary.c_str(), binary.c_str(), "-p", (d + "/").c_str(), "-e", err_path.c_str(), "-c",
              conf_path.c_str(), static_cast<char*>(nullptr));
      std::_Exit(127);
    }
    // Ready once it accepts a connection (5 s at most).
    const auto deadline = Clock::now() + std::chrono::seconds(5);
    for (;;) {
      int status = 0;
      if (::waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = -1;
        throw Error("nginx exited at startup (its message is above)");
      }
      try {
        ::close(connect_loopback(port_));
        break;
      } catch (const Error&) {
        if (Clock::now() > deadline) {
          stop();
          throw Error("nginx did not listen on 127.0.0.1:" + std::to_string(port_) + " within 5 s");
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
      }
    }
  }
  ~Nginx() { stop(); }
  Nginx(const Nginx&) = delete;
  Nginx& operator=(const Nginx&) = delete;
  uint16_t port() const { return port_; }

  void stop() {
    if (pid_ <= 0) return;
    ::kill(pid_, SIGTERM);
    const auto deadline = Clock::now() + std::chrono::seconds(3);
    int status = 0;
    while (::waitpid(pid_, &status, WNOHANG) == 0) {
      if (Clock::now() > deadline) {
        ::kill(pid_, SIGKILL);
        ::waitpid(pid_, &status, 0);
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    pid_ = -1;
  }

 private:
  fs::path dir_;
  uint16_t port_ = 0;
  pid_t pid_ = -1;
};

std::vector<std::string> split(const std::string& s) {
  std::vector<std::string> v;
  std::stringstream ss(s);
  for (std::string x; std::getline(ss, x, ',');)
    if (!x.empty()) v.push_back(x);
  return v;
}

}  // namespace

int main(int argc, char** argv) {
  uint32_t level = 10, depth = 8, threads = 1;
  // Our server keeps the pack open; nginx keeps tile file descriptors open the same way
  // (without it, open/fstat/close per request halved nginx's rate with 1 connection).
  // --nginx-extra "" gives the plain config.
  std::string nginx_extra = "open_file_cache max=65536 inactive=60s;";
  int skip = -1;  // cut level K; default level - 5: 1024 tiles of 32x32 texels, a few KiB each
  double seconds = 3, warmup = 0.3;
  std::string conns_arg = "1,8,64", workers_arg = "1,auto", nginx_arg, json_path = "bench-out/serve_vs_nginx.json";
  for (int i = 1; i + 1 < argc; i += 2) {
    std::string k = argv[i], v = argv[i + 1];
    if (k == "--level") level = uint32_t(std::stoul(v));
    else if (k == "--seconds") seconds = std::stod(v);
    else if (k == "--warmup") warmup = std::stod(v);
    else if (k == "--depth") depth = uint32_t(std::stoul(v));
    else if (k == "--conns") conns_arg = v;
    else if (k == "--nginx-workers") workers_arg = v;
    else if (k == "--nginx") nginx_arg = v;
    else if (k == "--nginx-extra") nginx_extra = v;
    else if (k == "--skip") skip = int(std::stoi(v));
    else if (k == "--json") json_path = v;
    else if (k == "--threads") threads = uint32_t(std::stoul(v));
    else {
      std::fprintf(stderr, "bench_serve_vs_nginx: unknown option %s\n", k.c_str());
      return 2;
    }
  }
  // Our GetTiles ids live in a 1024-slot ring and the server grants 64 in flight.
  depth = std::clamp<uint32_t>(depth, 1, 64);
  fs::path dir = fs::temp_directory_path() / ("shadowtile_bench_nginx_" + std::to_string(::getpid()));
  int rc = 0;
  try {
    fs::create_directories(dir);
    const std::string pack = (dir / "bench.pack").string();
    CutParams cut;
    cut.map_level = level;
    cut.skip_level = skip >= 0 ? uint32_t(skip) : std::min<uint32_t>(level - 5, 8);
    cut.codec = TileCodec::of(Encoding::mh);
    LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), Aabb{{-1, 0, -1}, {1, 1, 1}});
    write_pack(pack, build_hierarchy(bench_field(level)), cut, PackParams::from(light, cut));
    auto reader = std::shared_ptr<PackReader>(PackReader::open(pack));
    // The same stored bytes, one file per tile, for nginx.
    const fs::path www = dir / "www";
    fs::create_directories(www / "tiles");
    std::vector<uint64_t> ids;
    uint64_t stored = 0;
    for (auto& t : reader->tiles()) {
      ids.push_back(t.id);
      auto bytes = reader->read_stored(t.id);
      stored += bytes.size();
      std::ofstream(www / "tiles" / std::to_string(t.id), std::ios::binary)
          .write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
    }
    if (ids.empty()) throw Error("pack has no tiles");
    std::printf("pack: level %u, K %u, %zu tiles, %.2f MB stored (%.0f B/tile avg); depth %u, %.1f s per cell\n",
                level, cut.skip_level, ids.size(), double(stored) / 1e6, double(stored) / double(ids.size()), depth,
                seconds);

    const auto nginx_bin = find_nginx(nginx_arg);
    if (!nginx_bin)
      std::printf("nginx not found (PATH, /usr/sbin; or --nginx PATH): measuring ours only. "
                  "Install it with scripts/bench-serve or apt-get install nginx-light.\n");

    std::vector<int> conns;
    for (auto& c : split(conns_arg)) conns.push_back(std::stoi(c));
    std::vector<Cell> cells;
    {
      server::ServerOptions so;
      so.port = 0;
      so.threads = threads;
      so.log = [](const std::string&) {};
      server::Server srv(server::Catalog::scan(std::vector<std::string>{pack}), so);
      srv.start();
      for (int n : conns) cells.push_back(measure("ours", run_ours, srv.port(), ids, n, depth, warmup, seconds));
      srv.stop();
      std::printf("server: %s\n", srv.stats().line().c_str());
    }
    if (nginx_bin) {
      for (auto& wk : split(workers_arg)) {
        try {
          Nginx ng(*nginx_bin, dir / ("nginx_w" + wk), www, wk, nginx_extra);
          for (int n : conns)
            cells.push_back(measure("nginx w" + wk, run_http, ng.port(), ids, n, depth, warmup, seconds));
          ng.stop();
        } catch (const Error& e) {
          std::printf("nginx w%s skipped: %s\n", wk.c_str(), e.what());
        }
      }
    }

    std::printf("\n%6s %-11s %11s %9s %8s %8s %8s %12s\n", "conns", "server", "tiles/s", "MB/s", "p50 ms",
                "p99 ms", "p99.9 ms", "ours/this");
    nlohmann::json rows = nlohmann::json::array();
    for (int n : conns) {
      const Cell* ours = nullptr;
      for (auto& c : cells)
        if (c.conns == n && c.server == "ours") ours = &c;
      for (auto& c : cells) {
        if (c.conns != n) continue;
        const double ratio = c.tiles_per_s > 0 && ours ? ours->tiles_per_s / c.tiles_per_s : 0;
        std::printf("%6d %-11s %11.0f %9.1f %8.3f %8.3f %8.3f %12s\n", n, c.server.c_str(), c.tiles_per_s, c.mb_per_s,
                    c.p50_ms, c.p99_ms, c.p999_ms, &c == ours ? "-" : (std::to_string(ratio).substr(0, 5) + "x").c_str());
        rows.push_back({{"server", c.server}, {"connections", n}, {"tiles_per_s", c.tiles_per_s},
                        {"mb_per_s", c.mb_per_s}, {"p50_ms", c.p50_ms}, {"p99_ms", c.p99_ms},
                        {"p999_ms", c.p999_ms}, {"tiles", c.tiles},
                        {"ratio_ours_over_this", &c == ours ? nlohmann::json(nullptr) : nlohmann::json(ratio)}});
      }
    }
    const fs::path jp(json_path);
    if (!jp.parent_path().empty()) fs::create_directories(jp.parent_path());
    nlohmann::json j = {{"benchmark", "serve_vs_nginx"}, {"level", level}, {"tiles", ids.size()},
                        {"stored_bytes", stored}, {"depth", depth}, {"seconds", seconds},
                        {"warmup_seconds", warmup}, {"nginx", nginx_bin ? *nginx_bin : ""},
                        {"our_io_threads", 1}, {"nginx_extra", nginx_extra}, {"rows", rows}};
    std::ofstream(json_path) << j.dump(2) << "\n";
    std::printf("wrote %s\n", json_path.c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_serve_vs_nginx: %s\n", e.what());
    rc = 1;
  }
  std::error_code ec;
  fs::remove_all(dir, ec);
  return rc;
}
