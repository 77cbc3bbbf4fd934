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
// --rate-fraction F (0 < F <= 1) adds open-loop cells after the closed-loop ones: every
// connection sends one request per interval on a fixed schedule (the total rate F x our
// measured peak at that connection count, the same rate offered to nginx), whatever the
// answers do (up to 64 in flight), and latency is counted from the scheduled send time,
// so a stalled server cannot hide its queueing delay (no coordinated omission).
// --rate R fixes the total rate (requests/s) instead.
// "srv us/tile": the serving side's CPU time (user + system) per tile answered: ours is
// this process's CPU less the driver threads', nginx its process's (/proc, 10 ms steps).
// It depends far less on the machine's other load than the rates do.
// --reps N repeats every cell N times (servers alternating) and reports the median run's
// tiles/s and the median of each percentile.
//   bench_serve_vs_nginx [--level 10] [--seconds 3] [--warmup 0.3] [--depth 8]
//                        [--rate-fraction 0.5 | --rate R] [--reps 1]
//                        [--conns 1,8,64] [--nginx-workers 1,auto] [--nginx PATH] [--skip K]
//                        [--nginx-extra "open_file_cache max=65536 inactive=60s;"]
//                        [--json bench-out/serve_vs_nginx.json] [--threads T (our I/O threads)] [--busy-poll-us U]
//                        [--tile-cache-mib M (our payload cache; 0: pread + CRC per tile)]
#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <time.h>
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
#include <functional>
#include <iterator>
#include <nlohmann/json.hpp>
#include <optional>
#include <memory>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "bench/options.hpp"
#include "proto/proto.hpp"
#include "server/server.hpp"
#include "common/error.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/core/pack_reader.hpp"
#include "tiles/encode/pack_writer.hpp"
#include "bench/timing.hpp"

using namespace st;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

double since(Clock::time_point t0, Clock::time_point t1) { return std::chrono::duration<double>(t1 - t0).count(); }

using st::bench::thread_cpu_now;

double process_cpu_s() {
  rusage ru{};
  ::getrusage(RUSAGE_SELF, &ru);
  return double(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) + double(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec) * 1e-6;
}

// CPU seconds (user + system) of another process, from /proc (clock ticks: 10 ms steps).
double child_cpu_s(pid_t pid) {
  std::ifstream f("/proc/" + std::to_string(pid) + "/stat");
  std::string stat((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  const size_t close = stat.rfind(')');
  if (close == std::string::npos) return 0;
  std::istringstream rest(stat.substr(close + 2));
  std::string field;
  double ticks = 0;
  for (int i = 3; i <= 15 && rest >> field; ++i)
    if (i == 14 || i == 15) ticks += std::stod(field);
  return ticks / double(::sysconf(_SC_CLK_TCK));
}

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
  uint64_t all_tiles = 0;    // warm-up included: what the server CPU time below paid for
  double driver_cpu_s = 0;   // this driver thread's CPU time
  std::vector<double> latency_s;
  std::string error;
};

struct Window {
  Clock::time_point start, stop;
  bool counts(Clock::time_point t) const { return t >= start && t < stop; }
};

// What one connection offers: closed loop (`depth` in flight, a new request as soon as an
// answer is in) or open loop (interval > 0: one request every `interval` from `first`,
// at most kMaxOpenLoopInFlight in flight).
struct Load {
  uint32_t depth = 1;
  Clock::duration interval{0};
  Clock::time_point first{};
};
constexpr uint32_t kMaxOpenLoopInFlight = 64;

// Open loop: sends are due at `next`; the driver waits for an answer or the next due
// send, whichever comes first. Returns false if nothing is readable yet.
bool wait_readable(int fd, const Load& load, Clock::time_point next) {
  if (load.interval.count() == 0) return true;  // closed loop: a blocking recv
  const auto now = Clock::now();
  if (next <= now) {
    pollfd p{fd, POLLIN, 0};
    return ::poll(&p, 1, 0) > 0;
  }
  const auto ns = std::chrono::duration_cast<std::chrono::nanoseconds>(next - now).count();
  timespec ts{time_t(ns / 1000000000), long(ns % 1000000000)};
  pollfd p{fd, POLLIN, 0};
  return ::ppoll(&p, 1, &ts, nullptr) > 0;
}

// Our protocol: Hello, OpenMap, then GetTiles of one tile each, `depth` in flight.
void run_ours(uint16_t port, const std::vector<uint64_t>& ids, const Load& load, uint32_t seed, Window w,
              ConnResult& res) {
  const bool open_loop = load.interval.count() > 0;
  const uint32_t depth = open_loop ? kMaxOpenLoopInFlight : load.depth;
  Clock::time_point next = load.first;
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
      while (ready && in_flight < depth && (!open_loop || next <= now)) {
        proto::GetTiles g;
        g.map_id = 1;
        g.tiles.push_back({ids[rng() % ids.size()], 0});
        (void)proto::encode_message(g, next_id, proto::kFlagFinal, l, out);
        sent[next_id % sent.size()] = open_loop ? next : now;
        ++next_id, ++in_flight;
        if (open_loop) next += load.interval;
      }
      if (open_loop && ready && in_flight >= depth && next <= now) next = now + load.interval;  // overloaded: skip
      if (!out.empty()) send_all(fd, out.data(), out.size());
      if (!wait_readable(fd, load, ready ? next : now + std::chrono::milliseconds(100))) continue;
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
            ++res.all_tiles;
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
void run_http(uint16_t port, const std::vector<uint64_t>& ids, const Load& load, uint32_t seed, Window w,
              ConnResult& res) {
  const bool open_loop = load.interval.count() > 0;
  const uint32_t depth = open_loop ? kMaxOpenLoopInFlight : load.depth;
  Clock::time_point next = load.first;
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
      ++res.all_tiles;
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
      while (sent.size() < depth && (!open_loop || next <= now)) {
        out += "GET /tiles/" + std::to_string(ids[rng() % ids.size()]) + " HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n";
        sent.push_back(open_loop ? next : now);
        if (open_loop) next += load.interval;
      }
      if (open_loop && sent.size() >= depth && next <= now) next = now + load.interval;  // overloaded: skip
      if (!out.empty()) send_all(fd, out.data(), out.size());
      if (!wait_readable(fd, load, next)) continue;
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
  double server_cpu_us_per_tile = 0;  // the server's CPU time per tile answered (0: unknown)
  double offered_per_s = 0;  // open loop: the scheduled request rate; 0: closed loop
  double tiles_per_s = 0, mb_per_s = 0, p50_ms = 0, p99_ms = 0, p999_ms = 0;
  uint64_t tiles = 0;
};

double pct(const std::vector<double>& sorted, double p) {
  if (sorted.empty()) return 0;
  size_t i = size_t(p * double(sorted.size() - 1) + 0.5);
  return sorted[std::min(i, sorted.size() - 1)];
}

using Driver = void (*)(uint16_t, const std::vector<uint64_t>&, const Load&, uint32_t, Window, ConnResult&);
// The serving side's CPU seconds so far; null: this process's minus the drivers' (ours
// runs in-process).
using CpuProbe = std::function<double()>;

// rate > 0: open loop at `rate` requests/s in all, spread evenly over the connections.
Cell measure_once(const std::string& server, Driver drive, const CpuProbe& cpu, uint16_t port,
                  const std::vector<uint64_t>& ids, int conns, uint32_t depth, double rate, double warmup_s,
                  double seconds) {
  const double cpu0 = cpu ? cpu() : process_cpu_s();
  const auto t0 = Clock::now() + std::chrono::milliseconds(50);  // time for every thread to connect
  Window w;
  w.start = t0 + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(warmup_s));
  w.stop = w.start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds));
  std::vector<ConnResult> res(static_cast<size_t>(conns));
  std::vector<std::thread> th;
  for (int c = 0; c < conns; ++c)
    th.emplace_back([&, c] {
      try {
        Load load;
        load.depth = depth;
        if (rate > 0) {
          const double interval_s = double(conns) / rate;
          load.interval = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(interval_s));
          // Phases staggered over one interval: the connections do not send in bursts.
          load.first = t0 + std::chrono::duration_cast<Clock::duration>(
                                std::chrono::duration<double>(interval_s * double(c) / double(conns)));
        }
        // The open loop's sleeps end on time (the default 50 us timer slack would count
        // as server latency).
        ::prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL);
        const double c0 = thread_cpu_now();
        drive(port, ids, load, 1000u + uint32_t(c), w, res[size_t(c)]);
        res[size_t(c)].driver_cpu_s = thread_cpu_now() - c0;
      } catch (const std::exception& e) {
        res[size_t(c)].error = e.what();
      }
    });
  for (auto& t : th) t.join();
  double server_cpu = (cpu ? cpu() : process_cpu_s()) - cpu0;
  uint64_t all_tiles = 0;
  for (auto& r : res) {
    all_tiles += r.all_tiles;
    if (!cpu) server_cpu -= r.driver_cpu_s;
  }
  Cell cell;
  cell.server_cpu_us_per_tile = all_tiles ? std::max(0.0, server_cpu) * 1e6 / double(all_tiles) : 0;
  cell.server = server;
  cell.conns = conns;
  cell.offered_per_s = rate;
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

// The median of several runs: tiles/s and MB/s of the median run by rate, each
// percentile the median of the runs' percentiles.
Cell median_of(std::vector<Cell> runs) {
  auto med = [&](auto field) {
    std::vector<double> v;
    for (auto& r : runs) v.push_back(r.*field);
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
  };
  std::sort(runs.begin(), runs.end(), [](const Cell& a, const Cell& b) { return a.tiles_per_s < b.tiles_per_s; });
  Cell c = runs[runs.size() / 2];
  c.p50_ms = med(&Cell::p50_ms);
  c.p99_ms = med(&Cell::p99_ms);
  c.p999_ms = med(&Cell::p999_ms);
  c.server_cpu_us_per_tile = med(&Cell::server_cpu_us_per_tile);
  return c;
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
  pid_t pid() const { return pid_; }

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
  uint32_t level = 10, depth = 8, threads = 1, reps = 1, busy_poll_us = 0;
  double rate_fraction = 0, fixed_rate = 0;
  double tile_cache_mib = 64;  // our server's payload cache (0: pread and CRC per tile)
  // Our server keeps the pack open; nginx keeps tile file descriptors open the same way
  // (without it, open/fstat/close per request halved nginx's rate with 1 connection).
  // --nginx-extra "" gives the plain config.
  std::string nginx_extra = "open_file_cache max=65536 inactive=60s;";
  int skip = -1;  // cut level K; default level - 5: 1024 tiles of 32x32 texels, a few KiB each
  double seconds = 3, warmup = 0.3;
  std::string conns_arg = "1,8,64", workers_arg = "1,auto", nginx_arg, json_path = "bench-out/serve_vs_nginx.json";
  st::bench::Options opt("bench_serve_vs_nginx", "Our tile server against nginx serving the same tile bytes as static files");
  opt.value("--level", level, "Map level (side 2^level)")
      .value("--seconds", seconds, "Seconds per cell")
      .value("--warmup", warmup, "Warm-up seconds per cell")
      .value("--depth", depth, "Requests in flight per connection (1..64)")
      .value("--conns", conns_arg, "Connection counts, comma-separated")
      .value("--nginx-workers", workers_arg, "nginx worker counts, comma-separated (auto: the cores)")
      .value("--nginx", nginx_arg, "The nginx binary (default: nginx on PATH)")
      .value("--nginx-extra", nginx_extra, "Extra nginx http-block config (\"\" for the plain config)")
      .value("--skip", skip, "Cut level K (-1: level - 5, at most 8)")
      .value("--json", json_path, "Write the rows as JSON to PATH")
      .value("--threads", threads, "Our server's I/O threads")
      .value("--busy-poll-us", busy_poll_us, "Our server's busy-poll microseconds")
      .value("--reps", reps, "Runs per cell (servers alternating), the median reported")
      .value("--rate-fraction", rate_fraction, "Open-loop cells at F x our peak rate (0 < F <= 1; 0: none)")
      .value("--rate", fixed_rate, "Open-loop cells at R requests/s in all (0: none)")
      .value("--tile-cache-mib", tile_cache_mib, "Our payload cache in MiB (0: pread + CRC per tile)");
  opt.parse(argc, argv);
  reps = std::max<uint32_t>(1, reps);
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
    // Every server runs for the whole measurement, and each repetition measures them in
    // turn, so a noisy stretch of the shared machine hits all of them alike.
    server::ServerOptions so;
    so.port = 0;
    so.threads = threads;
    so.busy_poll = std::chrono::microseconds(busy_poll_us);
    so.tile_cache_bytes = size_t(tile_cache_mib * 1048576.0);
    so.log = [](const std::string&) {};
    server::Server srv(server::Catalog::scan(std::vector<std::string>{pack}), so);
    srv.start();
    struct Target {
      std::string name;
      Driver drive;
      CpuProbe cpu;
      uint16_t port;
    };
    std::vector<Target> targets{{"ours", run_ours, nullptr, srv.port()}};
    std::vector<std::unique_ptr<Nginx>> nginxes;
    if (nginx_bin)
      for (auto& wk : split(workers_arg)) {
        try {
          nginxes.push_back(std::make_unique<Nginx>(*nginx_bin, dir / ("nginx_w" + wk), www, wk, nginx_extra));
          const pid_t pid = nginxes.back()->pid();
          targets.push_back({"nginx w" + wk, run_http, [pid] { return child_cpu_s(pid); }, nginxes.back()->port()});
        } catch (const Error& e) {
          std::printf("nginx w%s skipped: %s\n", wk.c_str(), e.what());
        }
      }
    auto run_cells = [&](int n, double rate) {
      std::vector<std::vector<Cell>> runs(targets.size());
      for (uint32_t r = 0; r < reps; ++r)
        for (size_t t = 0; t < targets.size(); ++t)
          runs[t].push_back(
              measure_once(targets[t].name, targets[t].drive, targets[t].cpu, targets[t].port, ids, n, depth, rate,
                           warmup, seconds));
      std::vector<Cell> out;
      for (auto& r : runs) out.push_back(median_of(std::move(r)));
      return out;
    };
    std::vector<Cell> cells, open_cells;
    for (int n : conns)
      for (auto& c : run_cells(n, 0)) cells.push_back(c);
    if (rate_fraction > 0 || fixed_rate > 0)
      for (int n : conns) {
        double peak = 0;
        for (auto& c : cells)
          if (c.conns == n && c.server == "ours") peak = c.tiles_per_s;
        const double rate = fixed_rate > 0 ? fixed_rate : rate_fraction * peak;
        if (rate <= 0) continue;
        for (auto& c : run_cells(n, rate)) open_cells.push_back(c);
      }
    for (auto& ng : nginxes) ng->stop();
    srv.stop();
    std::printf("server: %s\n", srv.stats().line().c_str());

    nlohmann::json rows = nlohmann::json::array();
    auto table = [&](const std::vector<Cell>& cs, const char* title) {
      if (cs.empty()) return;
      std::printf("\n%s\n%6s %-11s %11s %11s %9s %8s %8s %8s %12s %10s\n", title, "conns", "server", "offered/s",
                  "tiles/s", "MB/s", "p50 ms", "p99 ms", "p99.9 ms", "srv us/tile", "ours/this");
      for (int n : conns) {
        const Cell* ours = nullptr;
        for (auto& c : cs)
          if (c.conns == n && c.server == "ours") ours = &c;
        for (auto& c : cs) {
          if (c.conns != n) continue;
          // Closed loop: the rate ratio; open loop (same offered rate): the p99 ratio nginx/ours.
          const bool open = c.offered_per_s > 0;
          double ratio = 0;
          if (ours && &c != ours)
            ratio = open ? (ours->p99_ms > 0 ? c.p99_ms / ours->p99_ms : 0)
                         : (c.tiles_per_s > 0 ? ours->tiles_per_s / c.tiles_per_s : 0);
          std::printf("%6d %-11s %11.0f %11.0f %9.1f %8.3f %8.3f %8.3f %12.2f %10s\n", n, c.server.c_str(),
                      c.offered_per_s, c.tiles_per_s, c.mb_per_s, c.p50_ms, c.p99_ms, c.p999_ms,
                      c.server_cpu_us_per_tile,
                      &c == ours ? "-" : (std::to_string(ratio).substr(0, 5) + "x").c_str());
          rows.push_back({{"server", c.server}, {"connections", n}, {"mode", open ? "open_loop" : "closed_loop"},
                          {"offered_per_s", c.offered_per_s}, {"tiles_per_s", c.tiles_per_s},
                          {"mb_per_s", c.mb_per_s}, {"p50_ms", c.p50_ms}, {"p99_ms", c.p99_ms},
                          {"p999_ms", c.p999_ms}, {"tiles", c.tiles},
                          {"server_cpu_us_per_tile", c.server_cpu_us_per_tile},
                          {open ? "p99_this_over_ours" : "ratio_ours_over_this",
                           &c == ours ? nlohmann::json(nullptr) : nlohmann::json(ratio)}});
        }
      }
    };
    table(cells, ("closed loop, depth " + std::to_string(depth) + ", median of " + std::to_string(reps) +
                  " run(s); ours/this = tiles/s ratio").c_str());
    table(open_cells, ("open loop (fixed schedule), median of " + std::to_string(reps) +
                       " run(s); ours/this = p99 of this / p99 of ours").c_str());
    const fs::path jp(json_path);
    if (!jp.parent_path().empty()) fs::create_directories(jp.parent_path());
    nlohmann::json j = {{"benchmark", "serve_vs_nginx"}, {"level", level}, {"tiles", ids.size()},
                        {"stored_bytes", stored}, {"depth", depth}, {"seconds", seconds},
                        {"warmup_seconds", warmup}, {"nginx", nginx_bin ? *nginx_bin : ""},
                        {"our_io_threads", threads}, {"our_busy_poll_us", busy_poll_us}, {"our_tile_cache_mib", tile_cache_mib}, {"nginx_extra", nginx_extra}, {"reps", reps},
                        {"rate_fraction", rate_fraction}, {"rate", fixed_rate}, {"rows", rows}};
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
