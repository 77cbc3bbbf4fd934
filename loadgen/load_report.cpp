#include "loadgen/load_report.hpp"

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "common/error.hpp"

namespace st::loadgen {

namespace {

std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

void write_text(const std::string& path, const std::string& text) {
  std::ofstream f(path);
  f << text;
  if (!f) throw Error(path + ": cannot write");
}

}  // namespace

std::string load_table(const LoadResult& r) {
  const auto& o = r.options;
  const auto& lat = r.latency_ms;
  std::string s;
  auto row = [&](const std::string& k, const std::string& v) {
    char buf[256];
    std::snprintf(buf, sizeof buf, "  %-34s %s\n", k.c_str(), v.c_str());
    s += buf;
  };
  s += "load: map '" + o.map + "' path " + to_string(o.path) + "\n";
  row("cameras / connections", std::to_string(o.cameras) + " / " + std::to_string(r.connections));
  row("duration (s) / rate (FPS)", fmt("%.1f", o.duration) + " / " + fmt("%.0f", o.rate));
  row("map level / skip level", std::to_string(r.map_level) + " / " + std::to_string(r.skip_level));
  if (r.slices)
    row("stack: slices / time", std::to_string(r.slices) + " / " +
                                    (o.soft ? std::string("soft (every slice)")
                                     : o.time0 == o.time1 ? fmt("%.3f", o.time0)
                                                          : fmt("%.3f", o.time0) + ".." + fmt("%.3f", o.time1) + " swept") +
                                    " (needed cells are slices)");
  row("cache per connection", fmt("%.1f MiB", o.cache_mb) + " (" + std::to_string(r.cache_slots) + " slots of " +
                                  std::to_string(r.slot_bytes) + " B; " +
                                  fmt("%.1f MiB", double(r.map.accounted_bytes) / 1048576 / std::max(1u, r.connections)) +
                                  " accounted), peak used " + std::to_string(r.peak_slots_used));
  row("prefetch", o.prefetch ? "on" : "off");
  row("threads: camera workers / client I/O", std::to_string(r.workers) + " / " + std::to_string(o.io_threads) +
                                                  " (residency poll up to " + fmt("%.0f ms", r.watcher_poll_ms_max) + ")");
  row("connects / disconnects", std::to_string(r.client.connects) + " / " + std::to_string(r.client.disconnects));
  row("frames (late)", std::to_string(r.frames) + " (" + std::to_string(r.frames_late) + "), max lag " +
                           fmt("%.1f ms", r.max_lag_ms));
  const FrameTimes& ft = r.frame_times;
  row("frame work ms mean/p50/p99/max", fmt("%.3f", ft.mean_ms()) + " / " + fmt("%.3f", ft.percentile_ms(.5)) + " / " +
                                            fmt("%.3f", ft.percentile_ms(.99)) + " / " + fmt("%.3f", ft.max_ms));
  if (r.slices && o.time0 != o.time1 && !o.soft) {
    const FrameTimes& ct = r.crossing_times;
    row("slice crossings: frames / holes / max ms", std::to_string(ct.frames) + " / " + std::to_string(r.crossing_holes) +
                                                        " / " + fmt("%.3f", ct.max_ms) + " (mean " +
                                                        fmt("%.3f", ct.mean_ms()) + ")");
  }
  row("frames with holes", std::to_string(r.frames_with_holes) + " (" + fmt("%.2f%%", 100 * r.hole_fraction()) + ")");
  row("  of them outside cut fill time", std::to_string(r.frames_with_holes_steady) + " (" +
                                           fmt("%.2f%%", r.frames ? 100.0 * double(r.frames_with_holes_steady) / double(r.frames) : 0) + ")");
  row("needed cells missing / needed", std::to_string(r.cells_missing) + " / " + std::to_string(r.cells_needed));
  row("tiles requested / received", std::to_string(r.map.tiles_requested) + " / " + std::to_string(r.map.tiles_received));
  row("tiles cancelled / failed", std::to_string(r.map.tiles_cancelled) + " / " + std::to_string(r.map.tiles_failed));
  row("bytes received (tiles / wire)", fmt("%.2f MiB", double(r.map.bytes_received) / 1048576) + " / " +
                                          fmt("%.2f MiB", double(r.client.bytes_received) / 1048576));
  row("cache hit rate", fmt("%.2f%%", 100 * r.cache_hit_rate()) + " (evictions " + std::to_string(r.map.cache.evictions) + ")");
  if (!r.slices)
    row("views: slots / over / overflows / refetches",
        std::to_string(r.map.view_slots) + " / " + std::to_string(r.map.view_tiles_over) + " / " +
            std::to_string(r.map.view_overflows) + " / " + std::to_string(r.map.view_refetches));
  row("lookups (mean ns, mean lit)", std::to_string(r.lookups) + " (" +
                                         fmt("%.0f", r.lookups ? r.lookup_seconds * 1e9 / double(r.lookups) : 0) +
                                         ", " + fmt("%.3f", r.mean_visibility) + ")");
  row("latency ms p50/p90/p99/p99.9/max",
      fmt("%.1f", percentile_of(lat, .5)) + " / " + fmt("%.1f", percentile_of(lat, .9)) + " / " +
          fmt("%.1f", percentile_of(lat, .99)) + " / " + fmt("%.1f", percentile_of(lat, .999)) + " / " +
          fmt("%.1f", percentile_of(lat, 1)) + "  (" + std::to_string(lat.size()) + " cells, " +
          std::to_string(r.latency_abandoned) + " abandoned)");
  row("cut -> full residency ms p50/p90/max",
      fmt("%.1f", percentile_of(r.cut_residency_ms, .5)) + " / " + fmt("%.1f", percentile_of(r.cut_residency_ms, .9)) +
          " / " + fmt("%.1f", percentile_of(r.cut_residency_ms, 1)) + "  (" + std::to_string(r.cut_residency_ms.size()) +
          " of " + std::to_string(r.cuts) + " cuts; " + std::to_string(r.cuts_incomplete) + " cut again first)");
  row("errors (crc/decode/failed/unanswered/proto/connect)",
      std::to_string(r.map.crc_errors) + "/" + std::to_string(r.map.decode_errors) + "/" +
          std::to_string(r.map.tiles_failed) + "/" + std::to_string(r.map.tiles_unanswered) + "/" +
          std::to_string(r.client.protocol_errors) + "/" + std::to_string(r.client.connect_failures) +
          (r.no_tile_received() ? "  (no tile received at all: counted as an error)" : ""));
  if (r.frames_skipped)
    row("frames skipped (past the duration)", std::to_string(r.frames_skipped));
  row("drained at end", r.drained ? "yes" : "no");
  return s;
}

std::string load_json(const LoadResult& r) {
  using nlohmann::json;
  const auto& o = r.options;
  json j;
  std::string server = o.endpoint.host + ":" + std::to_string(o.endpoint.port);
  for (const auto& r2 : o.replicas) server += "," + r2.host + ":" + std::to_string(r2.port);
  j["options"] = {{"server", server}, {"map", o.map},
                  {"cameras", o.cameras}, {"connections", r.connections}, {"path", to_string(o.path)},
                  {"duration_s", o.duration}, {"rate_fps", o.rate}, {"cache_mb", o.cache_mb}, {"seed", o.seed},
                  {"prefetch", o.prefetch}, {"samples_x", o.view.samples_x}, {"samples_y", o.view.samples_y},
                  {"workers", r.workers}, {"io_threads", o.io_threads}};
  j["connections"] = {{"connects", r.client.connects}, {"disconnects", r.client.disconnects},
                      {"connect_failures", r.client.connect_failures}};
  j["watcher_poll_ms_max"] = r.watcher_poll_ms_max;
  if (r.slices)
    j["stack"] = {{"slices", r.slices},
                  {"time0", o.time0},
                  {"time1", o.time1},
                  {"soft", o.soft},
                  {"crossings", {{"frames", r.crossing_times.frames},
                                 {"with_holes", r.crossing_holes},
                                 {"mean_ms", r.crossing_times.mean_ms()},
                                 {"max_ms", r.crossing_times.max_ms}}}};
  const FrameTimes& ft = r.frame_times;
  j["frame_ms"] = {{"frames", ft.frames}, {"mean", ft.mean_ms()}, {"p50", ft.percentile_ms(.5)},
                   {"p90", ft.percentile_ms(.9)}, {"p99", ft.percentile_ms(.99)}, {"max", ft.max_ms}};
  j["map"] = {{"level", r.map_level}, {"skip_level", r.skip_level}, {"cache_slots", r.cache_slots},
              {"slot_bytes", r.slot_bytes}, {"ground", r.world.ground}, {"top", r.world.top},
              {"footprint", {r.world.x0, r.world.z0, r.world.x1, r.world.z1}}};
  j["frames"] = {{"total", r.frames}, {"with_holes", r.frames_with_holes}, {"hole_fraction", r.hole_fraction()},
                 {"with_holes_outside_cut_fill", r.frames_with_holes_steady},
                 {"late", r.frames_late}, {"max_lag_ms", r.max_lag_ms}, {"cells_needed", r.cells_needed},
                 {"cells_missing", r.cells_missing}};
  j["tiles"] = {{"requested", r.map.tiles_requested}, {"received", r.map.tiles_received},
                {"cancelled", r.map.tiles_cancelled}, {"failed", r.map.tiles_failed},
                {"bytes_received", r.map.bytes_received}, {"wire_bytes_received", r.client.bytes_received},
                {"wire_bytes_sent", r.client.bytes_sent}, {"queue_full", r.map.queue_full},
                {"cache_full", r.map.cache_full}};
  j["cache"] = {{"hits", r.map.cache.hits}, {"misses", r.map.cache.misses}, {"hit_rate", r.cache_hit_rate()},
                {"evictions", r.map.cache.evictions}, {"inserts", r.map.cache.inserts},
                {"peak_slots_used", r.peak_slots_used}};
  j["views"] = {{"slots", r.map.view_slots}, {"tiles_wanted", r.map.view_tiles_wanted},
                {"tiles_over", r.map.view_tiles_over}, {"overflows", r.map.view_overflows},
                {"refetches", r.map.view_refetches}};
  j["lookups"] = {{"count", r.lookups}, {"seconds", r.lookup_seconds}, {"mean_visibility", r.mean_visibility}};
  const auto& lat = r.latency_ms;
  j["latency_ms"] = {{"count", lat.size()}, {"abandoned", r.latency_abandoned}, {"p50", percentile_of(lat, .5)},
                     {"p90", percentile_of(lat, .9)}, {"p99", percentile_of(lat, .99)},
                     {"p999", percentile_of(lat, .999)}, {"max", percentile_of(lat, 1)}};
  // The percentile curve a latency plot draws ([q, ms]; q = 1 is the maximum).
  json curve = json::array();
  if (!lat.empty())
    for (double q : {0.0, 0.1, 0.25, 0.5, 0.75, 0.9, 0.95, 0.98, 0.99, 0.995, 0.999, 0.9995, 0.9999, 0.99999, 1.0})
      curve.push_back({q, percentile_of(lat, q)});
  j["latency_ms"]["percentiles"] = curve;
  j["cut_residency_ms"] = {{"cuts", r.cuts}, {"completed", r.cut_residency_ms.size()},
                           {"incomplete", r.cuts_incomplete}, {"p50", percentile_of(r.cut_residency_ms, .5)},
                           {"p90", percentile_of(r.cut_residency_ms, .9)}, {"max", percentile_of(r.cut_residency_ms, 1)},
                           {"all", r.cut_residency_ms}};
  j["errors"] = {{"crc", r.map.crc_errors}, {"decode", r.map.decode_errors}, {"failed", r.map.tiles_failed},
                 {"unanswered", r.map.tiles_unanswered}, {"no_tile_received", r.no_tile_received()},
                 {"protocol", r.client.protocol_errors}, {"connect_failures", r.client.connect_failures},
                 {"total", r.errors()}};
  j["drained"] = r.drained;
  j["wall_seconds"] = r.wall_seconds;
  json series = json::array();
  for (const SeriesPoint& p : r.series)
    series.push_back({p.t, p.tiles_received, p.bytes, p.frames, p.frames_with_holes});
  j["series_columns"] = {"t_s", "tiles_received", "bytes", "frames", "frames_with_holes"};
  j["series"] = series;
  return j.dump(2);
}

void write_load_report(const LoadResult& r, const std::string& dir) {
  std::filesystem::create_directories(dir);
  write_text(dir + "/load.json", load_json(r) + "\n");
  write_text(dir + "/load.txt", load_table(r));
}

}  // namespace st::loadgen
