// `shadowtile load --server HOST:PORT --map NAME --cameras N --path P --duration S ...`:
// synthetic cameras against a running server through the client library only
// (loadgen/load_run.hpp); prints a table, writes JSON and an HTML page with --report DIR.
#include <cstdio>
#include <memory>

#include "app/html_page.hpp"
#include "loadgen/load_report.hpp"
#include "loadgen/load_run.hpp"
#include "app/command.hpp"
#include "app/connect_options.hpp"
#include "common/error.hpp"

namespace st::cli {

// "HOST:PORT" -> endpoint; throws st::Error naming the option.
client::Endpoint parse_endpoint(const std::string& option, const std::string& text) {
  const auto colon = text.rfind(':');
  if (colon == std::string::npos || colon == 0) throw Error(option + ": '" + text + "' is not HOST:PORT");
  std::string host = text.substr(0, colon), port = text.substr(colon + 1);
  if (host.size() > 2 && host.front() == '[' && host.back() == ']') host = host.substr(1, host.size() - 2);
  char* end = nullptr;
  const unsigned long p = std::strtoul(port.c_str(), &end, 10);
  if (port.empty() || *end != 0 || p == 0 || p > 65535) throw Error(option + ": bad port in '" + text + "'");
  return {host, uint16_t(p)};
}

// "T" -> [T, T]; "A..B" -> [A, B]; each in [0, 1]. Throws st::Error naming the option.
void parse_time_range(const std::string& option, const std::string& text, double& a, double& b) {
  auto number = [&](const std::string& s) {
    char* end = nullptr;
    const double v = std::strtod(s.c_str(), &end);
    if (s.empty() || *end != 0 || !(v >= 0 && v <= 1))
      throw Error(option + ": '" + text + "': expected a time in [0, 1]" +
                  (option == "--time-sweep" ? std::string(" or A..B") : std::string()));
    return v;
  };
  const auto dots = text.find("..");
  if (dots == std::string::npos) a = b = number(text);
  else a = number(text.substr(0, dots)), b = number(text.substr(dots + 2));
}

namespace {

struct LoadArgs {
  std::string server, map, path = "flyover", report;
  ConnectArgs connect;
  uint32_t cameras = 4, connections = 0, samples_x = 64, samples_y = 36, workers = 0, io_threads = 2;
  double duration = 10, rate = 60, cache_mb = 64;
  uint64_t seed = 1;
  bool no_prefetch = false;
  std::string time, time_sweep;
  bool soft = false;
};

void run_load(const LoadArgs& a) {
  loadgen::LoadOptions o;
  // --server A,B,C: replicas of one server (spread over, failed over between).
  for (size_t begin = 0;;) {
    const size_t comma = a.server.find(',', begin);
    client::Endpoint ep = parse_endpoint("--server", a.server.substr(begin, comma - begin));
    if (begin == 0) o.endpoint = ep;
    else o.replicas.push_back(ep);
    if (comma == std::string::npos) break;
    begin = comma + 1;
  }
  o.map = a.map;
  apply_connect_options(a.connect, o);
  o.cameras = a.cameras;
  o.connections = a.connections;
  o.path = loadgen::parse_path(a.path);
  o.duration = a.duration;
  o.rate = a.rate;
  o.cache_mb = a.cache_mb;
  o.seed = a.seed;
  o.prefetch = !a.no_prefetch;
  o.workers = a.workers;
  o.io_threads = a.io_threads;
  o.view.samples_x = a.samples_x;
  o.view.samples_y = std::max(1u, a.samples_x * 9 / 16);
  if (!a.time.empty() && !a.time_sweep.empty()) throw Error("load: give --time or --time-sweep, not both");
  if (!a.time.empty()) parse_time_range("--time", a.time, o.time0, o.time1);
  if (!a.time_sweep.empty()) {
    if (a.time_sweep.find("..") == std::string::npos) throw Error("--time-sweep: expected A..B, got '" + a.time_sweep + "'");
    parse_time_range("--time-sweep", a.time_sweep, o.time0, o.time1);
  }
  if (a.soft && !(a.time.empty() && a.time_sweep.empty())) throw Error("load: --soft reads every slice: no --time");
  o.soft = a.soft;
  const loadgen::LoadResult r = loadgen::run_load(o);
  std::printf("%s", loadgen::load_table(r).c_str());
  if (!a.report.empty()) {
    loadgen::write_load_report(r, a.report);
    std::printf("report: %s/load.{txt,json}\n", a.report.c_str());
    write_html_page("load", a.report + "/load.json", a.report + "/load.html");
  }
  if (r.errors() > 0) exit_with(kExitError);
}

Register reg_load{"load", "Load-test a server with synthetic cameras (client library only)", [](CLI::App& sub) {
  auto a = std::make_shared<LoadArgs>();
  sub.add_option("--server", a->server,
                 "Server address HOST:PORT, or replicas HOST:PORT,HOST:PORT,... (connections spread over "
                 "them and fail over when one goes away)")
      ->required();
  sub.add_option("--map", a->map, "Map name on the server")->required();
  sub.add_option("--cameras", a->cameras, "Synthetic cameras")->capture_default_str()->check(CLI::Range(1u, 4096u));
  sub.add_option("--connections", a->connections, "Client connections shared by the cameras (0: one per camera)")
      ->capture_default_str();
  sub.add_option("--path", a->path, "flyover | orbit | walk | teleport")->capture_default_str();
  sub.add_option("--duration", a->duration, "Seconds")->capture_default_str()->check(CLI::Range(0.01, 86400.0));
  sub.add_option("--rate", a->rate, "Frames per second per camera")->capture_default_str()->check(CLI::Range(0.1, 1000.0));
  sub.add_option("--cache-mb", a->cache_mb, "Tile cache per connection (MiB)")->capture_default_str()
      ->check(CLI::Range(0.01, 65536.0));
  sub.add_option("--report", a->report, "Write load.json, load.txt and load.html into this folder");
  sub.add_option("--seed", a->seed, "Path seed")->capture_default_str();
  add_connect_options(sub, a->connect);
  sub.add_option("--samples", a->samples_x, "Screen samples across (rows: 9/16 of it)")->capture_default_str()
      ->check(CLI::Range(1u, 1024u));
  sub.add_option("--workers", a->workers, "Camera threads (0: max(2, cores)); cameras are spread over them")
      ->capture_default_str()->check(CLI::Range(0u, 256u));
  sub.add_option("--io-threads", a->io_threads, "Client I/O threads shared by all connections")
      ->capture_default_str()->check(CLI::Range(1u, 64u));
  sub.add_flag("--no-prefetch", a->no_prefetch, "Do not prefetch along the path");
  sub.add_option("--time", a->time, "Stack maps: the light set's time T in [0, 1] (slices blended; default 0)");
  sub.add_option("--time-sweep", a->time_sweep,
                 "Stack maps: time A..B swept over the run (the slices around the current time requested, the "
                 "next ones prefetched)");
  sub.add_flag("--soft", a->soft, "Stack maps: soft shadows, the average over every slice (area lights)");
  sub.callback([a] { run_load(*a); });
}};

}  // namespace
}  // namespace st::cli
