// The lookup path a game calls: st::client::Map::visibility, single and batched, on a map
// whose every tile is resident in the client's cache, next to the uncompressed float
// array of the same map (the same world points, the same light-space transform, the same
// lit test) in the same run; and `render`'s map shadows against its Embree shadow rays
// for the demo's view.
//
//   bench_client_lookups [--scene city] [--light sun:azimuth=30,elevation=50] [--res 4k]
//                        [--encodings mh,mmh,dagmh] [--tile-bytes 8192] [--lookups 262144]
//                        [--batch 1024] [--reps 5] [--render-reps 3] [--threads 1,2] [--size 960x540]
//                        [--camera pos=-350,220,-380,target=0,0,0,fov=50] [--clock cpu|wall] [--quick]
//                        [--patterns random,coherent] [--kernels 1,5] [--subjects array,single,batch,filtered]
//                        [--pack P1,P2,...] [--json PATH]
//
// --pack: lookups on packs already built (`shadowtile build`; a real level's takes minutes)
// instead of building one per --encodings; the light is the packs' (all the same), the
// scene (--scene) only casts the render's rays, so give the one the packs were built from.
// Each encoding's pack is built with build_map into a temporary folder, then every tile
// is delivered to a client RemoteMap directly (RemoteMap::tile_arrived: CRC, inflate,
// open, exactly what the fetcher does; no socket), so lookups measure the cache, not the
// network. The float array is painted from that same map (depth of every finest texel).
//
// Patterns (world points at texel centres, receivers half just in front of the stored
// value, half just behind): random = uniform texels; coherent = runs of 256 consecutive
// texels along a row at random starts (a screen scanline in light space, roughly).
// Subjects: "array" (to_light + texel_of + compare, or 5x5 PCF with the Evaluator::pcf
// semantics), "single" (Map::visibility per point), "batch" (Map::visibility over spans of
// --batch points), "filtered" (Map::visibility_filtered over the same spans, a footprint
// of 3 finest texels: two levels blended). Kernels: single tap and 5x5 (pcf_radius 2).
// Threads: the points split in contiguous halves; figures are wall time per lookup of
// the whole pass (so two threads that scale show half the time) and the threads' CPU time
// per lookup, medians over --reps. Cost ratios (x array, /single, the targets) use CPU
// time unless --clock wall: on a shared machine other processes inflate wall time much
// more than the CPU time a pass itself spends; thread speed-ups use wall time.
// Before timing: batch == single == array bit for bit on every point, and the client's
// PCF (shared walk inside tiles) == the average of its single lookups on a sample.
// --quick: 2K^2, 64K lookups, 3 reps, one render rep. --render-only: only the render
// comparison (for profiling it). --patterns, --kernels (1: single tap, 5: 5x5) and
// --subjects time only those cells (checked as always), e.g. `--patterns coherent
// --kernels 5 --subjects batch` under perf; ratios and targets need the cells they divide.
// --profile-map N (with --render-only): the render's single taps alone through the client
// (its receivers, order and queries; pcf_batch over --batch queries) on one thread, N
// times, the median printed (for perf: the samples fall in the lookups); with --cold each
// pass after 64 MiB of other memory is written (as the render's passes find the caches
// after the rays and the image). It also prints the passes that kept their CPU (no
// involuntary context switch of the thread) apart from those that did not: on a loaded
// machine a pass that lost its core finds its caches cold when it comes back.
#include <sys/resource.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>

#include "bench/options.hpp"
#include "bench/bench_map.hpp"
#include "client/map_access.hpp"
#include "tiles/bake/map_build.hpp"
#include "render/render.hpp"
#include "tiles/core/camera.hpp"
#include "tiles/core/pack_evaluator.hpp"
#include "tiles/core/pack_reader.hpp"

namespace {

using namespace st::bench;
using st::client::WorldPoint;

struct Probe {
  WorldPoint p;
  uint64_t x = 0, y = 0;
};

struct Encoded {
  std::string name;
  std::shared_ptr<st::PackReader> reader;
  std::shared_ptr<st::client::RemoteMap> remote;
  st::client::Map map;
  uint64_t pack_bytes = 0, tiles = 0;
};

// Every tile of the pack into the map's cache, the way the fetcher delivers them.
void fill_cache(st::client::RemoteMap& m, const st::PackReader& reader) {
  const uint32_t L = reader.map_level();
  const uint64_t side = uint64_t(1) << L;
  uint32_t request_id = 1;
  for (;;) {
    m.request_region(L, 0, 0, side, side, 1);
    std::vector<st::proto::TileRequest> want;
    m.take_wanted(512, request_id, want);
    if (want.empty()) break;
    for (const auto& t : want) {
      const st::TileIndexEntry e = *reader.find(t.tile_id);
      st::proto::TileMeta meta;
      meta.tile_id = t.tile_id;
      meta.flags = st::proto::kTileFlagZlib;
      meta.uncompressed_size = e.raw_size;
      meta.payload_crc32 = e.crc;
      m.tile_arrived(meta, request_id, reader.read_stored(t.tile_id));
    }
    ++request_id;
  }
  if (!m.region_resident(L, 0, 0, side, side)) throw st::Error("fill_cache: the map is not wholly resident");
}

float array_visibility(const FloatMap& m, const st::LightSpace& light, const WorldPoint& w, uint32_t radius) {
  const st::LightPoint p = light.to_light({w.x, w.y, w.z});
  if (!(p.u >= 0 && p.u < 1 && p.v >= 0 && p.v < 1 && p.d >= 0 && p.d <= 1)) return 1.0f;
  const auto t = st::LightSpace::texel_of(m.level, p.u, p.v);
  const float receiver = float(p.d);
  if (radius == 0) return receiver <= m.at(t[0], t[1]) ? 1.0f : 0.0f;
  return array_pcf(m, t[0], t[1], 2 * radius + 1, receiver);
}

enum class Subject { array, single, batch, filtered };
const char* subject_name(Subject s) {
  switch (s) {
    case Subject::array: return "array";
    case Subject::single: return "single";
    case Subject::batch: return "batch";
    case Subject::filtered: return "filtered";
  }
  return "?";
}

struct PassTime {
  double wall = 0, cpu = 0;  // cpu: the threads' CPU seconds, summed
};

// One pass over `probes` on `threads` threads.
PassTime time_pass(Subject s, const Encoded& e, const FloatMap& arr, const st::LightSpace& light,
                 const std::vector<Probe>& probes, const std::vector<WorldPoint>& points,
                 const std::vector<float>& footprints, uint32_t radius, unsigned threads, size_t batch,
                 std::vector<float>& out) {
  std::atomic<double> cpu{0};
  auto work = [&](size_t begin, size_t end) {
    const double c0 = thread_cpu_now();
    switch (s) {
      case Subject::array:
        for (size_t i = begin; i < end; ++i) out[i] = array_visibility(arr, light, probes[i].p, radius);
        break;
      case Subject::single:
        for (size_t i = begin; i < end; ++i) out[i] = e.map.visibility(probes[i].p, 2 * radius + 1);
        break;
      case Subject::batch:
        for (size_t i = begin; i < end; i += batch) {
          const size_t n = std::min(batch, end - i);
          e.map.visibility(std::span(points).subspan(i, n), std::span(out).subspan(i, n), 2 * radius + 1);
        }
        break;
      case Subject::filtered:
        for (size_t i = begin; i < end; i += batch) {
          const size_t n = std::min(batch, end - i);
          e.map.visibility_filtered(std::span(points).subspan(i, n), std::span(footprints).subspan(i, n),
                                    std::span(out).subspan(i, n), 2 * radius + 1);
        }
        break;
    }
    cpu.fetch_add(thread_cpu_now() - c0);
  };
  const auto t0 = Clock::now();
  if (threads <= 1) {
    work(0, probes.size());
  } else {
    std::vector<std::thread> pool;
    const size_t per = (probes.size() + threads - 1) / threads;
    for (unsigned t = 0; t < threads; ++t)
      pool.emplace_back(work, std::min(probes.size(), t * per), std::min(probes.size(), (t + 1) * per));
    for (auto& th : pool) th.join();
  }
  return {seconds_since(t0), cpu.load()};
}

}  // namespace

int main(int argc, char** argv) {
  std::string scene_spec = "procedural:city", light_spec = "sun:azimuth=30,elevation=50", json_path;
  std::string camera_spec = "pos=-350,220,-380,target=0,0,0,fov=50", size_spec = "960x540";
  std::vector<std::string> enc_names{"mh", "mmh", "dagmh"}, pack_paths;
  std::vector<unsigned> thread_counts{1, 2};
  uint32_t level = 12, tile_bytes = 8192;
  size_t count = size_t(1) << 18, batch = 1024;
  int reps = 5, render_reps = 3;
  std::vector<std::string> pattern_names{"random", "coherent"}, subject_names{"array", "single", "batch", "filtered"};
  std::vector<uint32_t> radii{0, 2};
  int profile_map = 0;
  bool profile_cold = false;
  bool quick = false, level_given = false, use_cpu = true, render_reps_given = false, render_only = false;
  try {
    st::bench::Options opt("bench_client_lookups", "The client's lookups (single, batched, filtered) beside a float array, and render's map shadows");
    opt.value("--scene", scene_spec, "Scene spec (a bare name is procedural:NAME)")
        .value("--light", light_spec, "Light spec")
        .with("--res", [&](const std::string& v) { level = parse_level(v), level_given = true; }, "Map side (at least 512) [4k]")
        .with("--encodings", [&](const std::string& v) { enc_names = split_list(v); }, "mh, mmh, dagmh (comma-separated) [mh,mmh,dagmh]")
        .value("--tile-bytes", tile_bytes, "Tile budget in bytes")
        .with("--lookups", [&](const std::string& v) { count = size_t(std::max(1024ll, std::stoll(v))); }, "Lookups per pattern (at least 1024) [262144]")
        .with("--batch", [&](const std::string& v) { batch = size_t(std::max(1ll, std::stoll(v))); }, "Points per batch [1024]")
        .with("--reps", [&](const std::string& v) { reps = std::max(1, std::stoi(v)); }, "Median of R passes [5]")
        .with("--render-reps", [&](const std::string& v) { render_reps = std::max(1, std::stoi(v)), render_reps_given = true; }, "Render passes [3]")
        .with("--threads", [&](const std::string& v) {
                thread_counts.clear();
                for (const auto& t : split_list(v)) thread_counts.push_back(unsigned(std::clamp(std::stoi(t), 1, 64)));
              }, "Thread counts, comma-separated (1..64) [1,2]")
        .value("--size", size_spec, "The render's view WxH (at most 8192x8192)")
        .value("--camera", camera_spec, "The render's camera spec")
        .flag("--quick", quick, "2K^2, 64K lookups, 3 reps, one render rep")
        .flag("--render-only", render_only, "Only the render comparison")
        .with("--profile-map", [&](const std::string& v) { profile_map = std::max(1, std::stoi(v)); }, "With --render-only: the render's single taps alone through the client, N times")
        .flag("--cold", profile_cold, "With --profile-map: each pass after 64 MiB of other memory is written")
        .with("--patterns", [&](const std::string& v) { pattern_names = split_list(v); }, "random, coherent (comma-separated)")
        .with("--subjects", [&](const std::string& v) { subject_names = split_list(v); }, "array, single, batch, filtered (comma-separated)")
        .with("--kernels", [&](const std::string& v) {
                radii.clear();
                for (const auto& k : split_list(v)) {
                  if (k != "1" && k != "5") throw st::Error("--kernels: expected 1 or 5, got '" + k + "'");
                  radii.push_back(k == "1" ? 0u : 2u);
                }
              }, "1 (single tap), 5 (5x5 PCF), comma-separated [1,5]")
        .value("--json", json_path, "Write the rows as JSON to PATH")
        .with("--pack", [&](const std::string& v) { pack_paths = split_list(v); }, "Packs already built, comma-separated (P1,P2,...): lookups on them instead of building")
        .with("--clock", [&](const std::string& c) {
                if (c != "cpu" && c != "wall") throw st::Error("--clock: expected cpu or wall, got '" + c + "'");
                use_cpu = c == "cpu";
              }, "The clock of the cost ratios: cpu or wall [cpu]");
    opt.parse(argc, argv);
    if (scene_spec.find(':') == std::string::npos && !std::filesystem::exists(scene_spec))
      scene_spec = "procedural:" + scene_spec;  // a bare name; a file path stays a file
    if (quick) {
      if (!level_given) level = 11;
      count = std::min<size_t>(count, size_t(1) << 16);
      reps = std::min(reps, 3);
      if (!render_reps_given) render_reps = 1;
    }
    // Packs given: their level and light (all alike), opened before anything is printed.
    std::vector<std::shared_ptr<st::PackReader>> given;
    for (const std::string& p : pack_paths) {
      given.push_back(st::PackReader::open(p));
      if (given.back()->stack()) throw st::Error("--pack: " + p + " is a stack pack (a light set): not one map");
      if (given.size() > 1 && (given.back()->map_level() != given[0]->map_level() ||
                               given.back()->header().light != given[0]->header().light))
        throw st::Error("--pack: " + p + " has another resolution or light than " + pack_paths[0]);
      level = given.back()->map_level();
    }
    if (level < 9) throw st::Error("--res must be at least 512");
    uint32_t width = 0, height = 0;
    if (std::sscanf(size_spec.c_str(), "%ux%u", &width, &height) != 2 || width == 0 || height == 0 ||
        width > 8192 || height > 8192)
      throw st::Error("--size: expected WxH (at most 8192x8192), got '" + size_spec + "'");
    const uint64_t side = uint64_t(1) << level;
    std::printf("bench_client_lookups: %s, %s, %s^2, %zu lookups per pattern, batches of %zu, median of %d, load %.1f\n",
                scene_spec.c_str(), given.empty() ? light_spec.c_str() : "the packs' light", side_name(level).c_str(),
                count, batch, reps, load_average());
    std::fflush(stdout);

    const st::Scene scene = st::load_scene(scene_spec);
    const st::LightSpace light = given.empty() ? st::LightSpace::fit(st::LightSpec::parse(light_spec), scene.bounds())
                                               : given[0]->light();
    if (!given.empty() && given[0]->header().scene_hash != scene.content_hash())
      std::fprintf(stderr, "bench_client_lookups: warning: --scene is not the scene the packs were built from\n");
    const std::filesystem::path dir =
        std::filesystem::temp_directory_path() / ("bench_client_lookups." + std::to_string(getpid()));
    std::filesystem::create_directories(dir);
    struct RemoveDir {
      std::filesystem::path p;
      ~RemoveDir() {
        std::error_code ec;
        std::filesystem::remove_all(p, ec);
      }
    } remove_dir{dir};

    std::vector<Encoded> encoded;
    const size_t sources = given.empty() ? enc_names.size() : given.size();
    for (size_t k = 0; k < sources; ++k) {
      auto t0 = Clock::now();
      Encoded e;
      if (given.empty()) {
        const std::string& name = enc_names[k];
        st::MapBuildOptions o;
        o.map_level = level;
        o.encoding = st::parse_encoding(name);
        o.tile_bytes = tile_bytes;
        o.scene_spec = scene_spec, o.light_spec = light_spec;
        const std::string path = (dir / (name + ".pack")).string();
        const st::MapBuildReport rep = st::build_map(scene, light, o, path);
        e.name = name;
        e.reader = st::PackReader::open(path);
        e.pack_bytes = rep.pack_bytes;
      } else {
        e.reader = given[k];
        e.name = st::to_string(e.reader->header().encoding);
        for (const Encoded& o : encoded)
          if (o.name == e.name) {
            char suffix[24];
            std::snprintf(suffix, sizeof suffix, "#%zu", k);
            e.name.append(suffix);
          }
        e.pack_bytes = std::filesystem::file_size(pack_paths[k]);
      }
      e.tiles = e.reader->tiles().size();
      st::client::ClientOptions co;
      co.cache_slots = uint32_t(e.tiles + 16);
      co.want_capacity = uint32_t(e.tiles + 16);
      co.max_slot_bytes = 1u << 30;
      const auto h = e.reader->header_bytes();
      const auto g = e.reader->grid_bytes();
      e.remote = std::make_shared<st::client::RemoteMap>(e.name, std::vector<uint8_t>(h.begin(), h.end()),
                                                         std::vector<uint8_t>(g.begin(), g.end()), co,
                                                         std::make_shared<st::client::Notifier>());
      fill_cache(*e.remote, *e.reader);
      e.map = st::client::MapAccess::wrap(e.remote);
      // Where the client holds the tiles (client/tile_arena.hpp): map tiles once, in the arena;
      // slot bytes only for index tiles.
      const st::client::MapStats ms = e.remote->stats();
      std::printf("  %-6s pack %10llu bytes, %6llu tiles, %s and made resident in %.1f s (arena %.2f MiB, slot bytes "
                  "written %.2f MiB, %u slots)\n",
                  e.name.c_str(), (unsigned long long)e.pack_bytes, (unsigned long long)e.tiles,
                  given.empty() ? "built" : "opened", seconds_since(t0), double(ms.arena_bytes) / 1048576,
                  double(ms.slot_bytes_written) / 1048576, ms.tile_slots);
      std::fflush(stdout);
      encoded.push_back(std::move(e));
    }
    if (encoded.empty()) throw st::Error("--encodings: none given");

    // Probe positions: texel centres; receivers from the first encoding's values.
    FloatMap arr(level);
    auto paint = [&](const Encoded& e) {
      for (uint64_t y = 0; y < side; ++y)
        for (uint64_t x = 0; x < side; ++x) arr.data[y * side + x] = e.remote->depth(level, x, y);
    };
    if (!render_only) paint(encoded[0]);
    std::mt19937_64 rng(20261201);
    auto make_probe = [&](uint64_t x, uint64_t y) {
      const st::LightRay ray = light.texel_ray(level, x, y);
      const double v = arr.at(x, y);
      const double d = std::clamp((rng() & 1) ? v + 1e-4 : v - 1e-4, 0.0, 1.0);
      const st::Vec3d w = ray.origin + ray.dir * d;
      return Probe{{w.x, w.y, w.z}, x, y};
    };
    std::vector<Probe> random(count), coherent(count);
    for (auto& p : random) p = make_probe(rng() & (side - 1), rng() & (side - 1));
    for (size_t i = 0; i < count; i += 256) {
      const uint64_t x0 = rng() % (side - 256), y = rng() & (side - 1);
      for (size_t k = 0; k < 256 && i + k < count; ++k) coherent[i + k] = make_probe(x0 + k, y);
    }
    const double texel_world = light.extent_uv() / double(side);
    std::vector<float> footprints(count, float(3 * texel_world));

    struct Result {
      std::string encoding, pattern, subject;
      uint32_t radius = 0;
      unsigned threads = 1;
      double seconds = 0, cpu = 0;  // medians: wall and summed thread CPU seconds per pass
    };
    std::vector<Result> results;
    uint64_t mismatches = 0, pcf_mismatches = 0, filtered_mismatches = 0, render_mismatches = 0;
    const std::pair<const char*, const std::vector<Probe>*> patterns[] = {{"random", &random}, {"coherent", &coherent}};
    std::vector<float> out(count), ref(count);
    for (size_t ei = 0; ei < (render_only ? 0 : encoded.size()); ++ei) {
      const Encoded& e = encoded[ei];
      if (ei > 0) paint(e);  // the float array of this same map
      for (auto& [pname, list] : patterns) {
        if (std::find(pattern_names.begin(), pattern_names.end(), pname) == pattern_names.end()) continue;
        std::vector<WorldPoint> points(list->size());
        for (size_t i = 0; i < points.size(); ++i) points[i] = (*list)[i].p;
        // Checks before timing.
        for (uint32_t radius : radii) {
          time_pass(Subject::array, e, arr, light, *list, points, footprints, radius, 1, batch, ref);
          for (Subject s : {Subject::single, Subject::batch}) {
            time_pass(s, e, arr, light, *list, points, footprints, radius, 1, batch, out);
            for (size_t i = 0; i < count; ++i) mismatches += std::bit_cast<uint32_t>(out[i]) != std::bit_cast<uint32_t>(ref[i]);
          }
          time_pass(Subject::filtered, e, arr, light, *list, points, footprints, radius, 1, batch, out);
          for (size_t i = 0; i < std::min<size_t>(count, 4096); ++i)
            filtered_mismatches += std::bit_cast<uint32_t>(out[i]) !=
                                   std::bit_cast<uint32_t>(e.map.visibility_filtered(points[i], footprints[i], 2 * radius + 1));
        }
        for (size_t i = 0; i < std::min<size_t>(count, 4096); ++i)
          for (uint32_t r : {3u, 5u, 9u}) {
            const Probe& q = (*list)[i];
            const float recv = float(light.to_light({q.p.x, q.p.y, q.p.z}).d);
            pcf_mismatches += e.remote->pcf(level, q.x, q.y, r, recv) != e.remote->Evaluator::pcf(level, q.x, q.y, r, recv);
          }
        for (uint32_t radius : radii)
          for (unsigned threads : thread_counts) {
            std::vector<Subject> subjects;
            for (Subject s : {Subject::array, Subject::single, Subject::batch, Subject::filtered})
              if (std::find(subject_names.begin(), subject_names.end(), subject_name(s)) != subject_names.end())
                subjects.push_back(s);
            std::vector<std::vector<double>> t(std::size(subjects)), c(std::size(subjects));
            for (int rep = 0; rep < reps + 1; ++rep)  // the first pass warms up
              for (size_t s = 0; s < std::size(subjects); ++s) {
                const PassTime pt = time_pass(subjects[s], e, arr, light, *list, points, footprints, radius, threads, batch, out);
                if (rep > 0) t[s].push_back(pt.wall), c[s].push_back(pt.cpu);
              }
            for (size_t s = 0; s < std::size(subjects); ++s)
              results.push_back({e.name, pname, subject_name(subjects[s]), radius, threads, median(t[s]), median(c[s])});
          }
      }
      std::printf("  %-6s timed\n", e.name.c_str());
      std::fflush(stdout);
    }

    // Cost ratios from CPU time (--clock cpu, the default: a pass's summed thread CPU
    // seconds, which other processes on a busy machine inflate far less than wall time)
    // or wall time; thread speed-ups always from wall time.
    auto find_in = [&](bool cpu_time, const std::string& enc, const std::string& p, const std::string& s,
                       uint32_t radius, unsigned th) {
      for (const Result& x : results)
        if (x.encoding == enc && x.pattern == p && x.subject == s && x.radius == radius && x.threads == th)
          return cpu_time ? x.cpu : x.seconds;
      return 0.0;
    };
    auto find = [&](const std::string& enc, const std::string& p, const std::string& s, uint32_t radius, unsigned th) {
      return find_in(use_cpu, enc, p, s, radius, th);
    };
    auto find_wall = [&](const std::string& enc, const std::string& p, const std::string& s, uint32_t radius,
                         unsigned th) { return find_in(false, enc, p, s, radius, th); };
    std::printf("\nClient lookups, every tile resident (%s^2; ns = wall ns per lookup of the whole pass; cpu ns = "
                "thread CPU ns per lookup; x array = %s time / the float array's, same points, kernel and threads; "
                "/single = 5x5 time / single-tap time; speed-up = 1-thread wall time / this wall time)\n",
                side_name(level).c_str(), use_cpu ? "CPU" : "wall");
    std::printf("%-6s %-9s %-6s %-8s %4s %9s %9s %9s %8s %9s\n", "enc", "pattern", "kernel", "subject", "thr", "ns",
                "cpu ns", "x array", "/single", "speed-up");
    nlohmann::json jres = nlohmann::json::array();
    for (const Result& x : results) {
      const double ns = 1e9 * x.seconds / double(count), cpu_ns = 1e9 * x.cpu / double(count);
      const double mine = use_cpu ? x.cpu : x.seconds;
      const double vs_array = mine / find(x.encoding, x.pattern, "array", x.radius, x.threads);
      const double vs_single = mine / find(x.encoding, x.pattern, x.subject, 0, x.threads);
      const double speedup = find_wall(x.encoding, x.pattern, x.subject, x.radius, 1) / x.seconds;
      std::printf("%-6s %-9s %-6s %-8s %4u %9.1f %9.1f %9.2f %8.2f %9.2f\n", x.encoding.c_str(), x.pattern.c_str(),
                  x.radius ? "5x5" : "single", x.subject.c_str(), x.threads, ns, cpu_ns, vs_array, vs_single, speedup);
      jres.push_back({{"encoding", x.encoding}, {"pattern", x.pattern}, {"subject", x.subject},
                      {"kernel", 2 * x.radius + 1}, {"threads", x.threads}, {"seconds_per_pass", x.seconds},
                      {"cpu_seconds_per_pass", x.cpu}, {"lookups_per_pass", count}, {"ns_per_lookup", ns},
                      {"cpu_ns_per_lookup", cpu_ns}, {"ratio_to_float_array", vs_array},
                      {"ratio_to_single", vs_single}, {"speedup_over_1_thread", speedup}});
    }

    // render's map shadows against its Embree shadow rays (RenderResult::map_seconds and
    // traced_seconds), for the same receivers.
    // The same receivers through two evaluators: the client's cache ("client", what a game
    // and `render --server` use) and PackEvaluator over the pack file ("pack", what `render
    // PACK` uses), every tile resident in both (one untimed pass first). ns per receiver =
    // the map pass's (or the rays') CPU time / the light-facing receivers.
    std::printf("\nrender %ux%u, %s: map shadows vs Embree shadow rays (median of %d; ns/recv from %s time)\n",
                width, height, camera_spec.c_str(), render_reps, use_cpu ? "CPU" : "wall");
    const st::SceneTracer tracer(scene, light);
    const std::vector<st::Receiver> receivers = tracer.primary(st::parse_camera(camera_spec), width, height);
    std::printf("%-8s %-6s %9s %9s %9s %9s %9s %11s %11s %9s %8s\n", "enc", "eval", "receivers", "map ms",
                "map cpu", "rays ms", "rays cpu", "map ns/rcv", "rays ns/rcv", "map/rays", "differ");
    if (profile_map > 0) {
      // The render's single taps alone, on this thread: its light-facing receivers in its
      // order (8x8-pixel screen tiles), sun_tap_queries, then pcf_batch over chunks of
      // `batch` queries, N passes (for perf: the samples fall in the lookups). Prints the
      // median thread-CPU ns per query.
      constexpr uint32_t kGather = 8;
      std::vector<st::Receiver> facing;
      for (uint32_t ty = 0; ty < height; ty += kGather)
        for (uint32_t tx = 0; tx < width; tx += kGather)
          for (uint32_t y = ty; y < std::min(height, ty + kGather); ++y)
            for (uint32_t x = tx; x < std::min(width, tx + kGather); ++x) {
              const st::Receiver& r = receivers[size_t(y) * width + x];
              if (r.hit && r.n_dot_l > 0) facing.push_back(r);
            }
      if (light.kind() != st::LightKind::sun) throw st::Error("--profile-map: a sun light only");
      std::vector<st::PcfQuery> queries(facing.size());
      std::vector<uint32_t> index(facing.size());
      queries.resize(st::sun_tap_queries(light, level, 0, facing, queries.data(), index.data()));
      std::vector<float> answers(queries.size());
      auto switches = [] {  // this thread's involuntary context switches so far
        rusage u{};
        getrusage(RUSAGE_THREAD, &u);
        return u.ru_nivcsw;
      };
      for (const Encoded& e : encoded) {
        std::vector<double> cpu, kept, lost;
        std::vector<long> lost_switches;
        std::vector<uint8_t> other(profile_cold ? size_t(64) << 20 : 0);
        for (int rep = 0; rep < profile_map + 1; ++rep) {  // the first pass warms up
          for (size_t i = 0; i < other.size(); i += 64) other[i] = uint8_t(other[i] + rep);
          const long s0 = switches();
          const double c0 = thread_cpu_now();
          for (size_t i = 0; i < queries.size(); i += batch) {
            const size_t n = std::min(batch, queries.size() - i);
            e.remote->pcf_batch(std::span(queries).subspan(i, n), std::span(answers).subspan(i, n));
          }
          const double c = thread_cpu_now() - c0;
          if (rep == 0) continue;
          cpu.push_back(c);
          lost_switches.push_back(switches() - s0);
          (lost_switches.back() == 0 ? kept : lost).push_back(c);
        }
        const double per = 1e9 / double(std::max<size_t>(queries.size(), 1));
        std::printf("%-8s client taps of the render, one thread, batches of %zu: median %.2f ms CPU, %.1f ns per "
                    "query (%zu); passes that kept their core %.1f ns (%zu), that lost it %.1f ns (%zu)\n",
                    e.name.c_str(), batch, 1e3 * median(cpu), per * median(cpu), queries.size(),
                    kept.empty() ? 0.0 : per * median(kept), kept.size(), lost.empty() ? 0.0 : per * median(lost),
                    lost.size());
        std::printf("  (anonymous memory in huge pages: %.1f MiB) each pass, ns per query / its involuntary context switches:",
                    anon_huge_mib());
        for (size_t k = 0; k < cpu.size(); ++k) std::printf(" %.1f/%ld", per * cpu[k], lost_switches[k]);
        std::printf("\n");
      }
      return 0;
    }
    nlohmann::json jrender = nlohmann::json::array();
    for (const Encoded& e : encoded) {
      const st::PackEvaluator pack_eval(e.reader, e.tiles + 16);
      const std::pair<const char*, const st::Evaluator*> evals[] = {{"client", e.remote.get()}, {"pack", &pack_eval}};
      for (const auto& [eval_name, eval] : evals) {
        st::RenderOptions ro;
        ro.width = width, ro.height = height, ro.diff = true;
        std::vector<double> ms, ts, mc, tc, gs, gc;
        uint64_t recv = 0, differing = 0;
        {
          // Untimed: fills the pack evaluator's cache; then the render's answers, bit for
          // bit those of one map_visibility per receiver (the single-lookup path).
          const st::RenderResult rr = st::render_view(tracer, receivers, *eval, ro);
          for (size_t i = 0; i < receivers.size(); ++i)
            render_mismatches += std::bit_cast<uint32_t>(rr.visibility[i]) !=
                                 std::bit_cast<uint32_t>(st::map_visibility(*e.remote, receivers[i], light, 0, level));
        }
        for (int rep = 0; rep < render_reps; ++rep) {
          const st::RenderResult rr = st::render_view(tracer, receivers, *eval, ro);
          gs.push_back(rr.gather_seconds), gc.push_back(rr.gather_cpu_seconds);
          ms.push_back(rr.map_seconds), ts.push_back(rr.traced_seconds);
          mc.push_back(rr.map_cpu_seconds), tc.push_back(rr.traced_cpu_seconds);
          recv = rr.receivers, differing = rr.differing;
        }
        const double m = median(ms), t = median(ts), m_cpu = median(mc), t_cpu = median(tc);
        // The G-buffer gather (RenderResult::gather_seconds): before both passes, in neither.
        const double g = median(gs), g_cpu = median(gc);
        const double ratio = use_cpu ? m_cpu / t_cpu : m / t;
        const double per = recv ? 1e9 / double(recv) : 0;
        const double map_ns = (use_cpu ? m_cpu : m) * per, rays_ns = (use_cpu ? t_cpu : t) * per;
        std::printf("%-8s %-6s %9llu %9.2f %9.2f %9.2f %9.2f %11.1f %11.1f %9.3f %8llu\n", e.name.c_str(), eval_name,
                    (unsigned long long)recv, 1e3 * m, 1e3 * m_cpu, 1e3 * t, 1e3 * t_cpu, map_ns, rays_ns, ratio,
                    (unsigned long long)differing);
        jrender.push_back({{"encoding", e.name}, {"evaluator", eval_name}, {"receivers", recv}, {"map_seconds", m},
                           {"traced_seconds", t}, {"map_cpu_seconds", m_cpu}, {"traced_cpu_seconds", t_cpu},
                           {"map_ns_per_receiver", map_ns}, {"rays_ns_per_receiver", rays_ns},
                           {"ratio_map_to_rays", ratio}, {"differing", differing}, {"gather_seconds", g},
                           {"gather_cpu_seconds", g_cpu}});
      }
    }
    std::printf("  (map/rays target <= 0.5 on real levels, goal 0.2; the gather of the G-buffer is in neither pass)\n");

    std::printf("\nTargets (single thread unless said; batch is the API a game calls per frame):\n");
    nlohmann::json targets = nlohmann::json::array();
    for (size_t ei = 0; ei < (render_only ? 0 : encoded.size()); ++ei)
      for (auto& [pname, list] : patterns) {
        const Encoded& e = encoded[ei];
        (void)list;
        if (find(e.name, pname, "array", 0, 1) == 0 || find(e.name, pname, "batch", 0, 1) == 0 ||
            find(e.name, pname, "batch", 2, 1) == 0 || find_wall(e.name, pname, "batch", 0, thread_counts.back()) == 0)
          continue;  // not all timed (--patterns, --kernels, --subjects)
        const double single = find(e.name, pname, "batch", 0, 1) / find(e.name, pname, "array", 0, 1);
        const double pcf = find(e.name, pname, "batch", 2, 1) / find(e.name, pname, "batch", 0, 1);
        const unsigned tn = thread_counts.back();
        const double scale = find_wall(e.name, pname, "batch", 0, 1) / find_wall(e.name, pname, "batch", 0, tn);
        std::printf("  %-6s %-9s batch single tap = %.2fx array (<= 1 %s); 5x5 = %.2fx single (<= 2 %s); "
                    "%u threads = %.2fx one (>= 1.8 %s)\n",
                    e.name.c_str(), pname, single, single <= 1 ? "met" : "NOT met", pcf, pcf <= 2 ? "met" : "NOT met",
                    tn, scale, scale >= 1.8 ? "met" : "NOT met");
        targets.push_back({{"encoding", e.name}, {"pattern", pname}, {"batch_single_over_array", single},
                           {"batch_pcf5_over_single", pcf}, {"thread_speedup", scale}, {"threads", tn}});
      }
    std::printf("  checks: %llu batch/single/array mismatches, %llu PCF shared-walk mismatches, %llu filtered "
                "batch/single mismatches, %llu render/map_visibility mismatches (load %.1f)\n",
                (unsigned long long)mismatches, (unsigned long long)pcf_mismatches,
                (unsigned long long)filtered_mismatches, (unsigned long long)render_mismatches, load_average());

    if (!json_path.empty()) {
      nlohmann::json j{{"bench", "client_lookups"}, {"scene", scene_spec}, {"light", given.empty() ? light_spec : "packs"},
                       {"packs_given", pack_paths}, {"camera", camera_spec}, {"size", size_spec}, {"side", side},
                       {"level", level}, {"tile_bytes", tile_bytes}, {"lookups_per_pattern", count},
                       {"batch", batch}, {"reps", reps}, {"clock", use_cpu ? "cpu" : "wall"}, {"mismatches", mismatches},
                       {"pcf_mismatches", pcf_mismatches}, {"filtered_mismatches", filtered_mismatches},
                       {"render_mismatches", render_mismatches},
                       {"load_average_end", load_average()}, {"results", jres}, {"render", jrender},
                       {"targets", targets}};
      for (const Encoded& e : encoded)
        j["packs"].push_back({{"encoding", e.name}, {"bytes", e.pack_bytes}, {"tiles", e.tiles}});
      std::ofstream f(json_path);
      if (!(f << j.dump(2) << "\n")) throw st::Error("bench_client_lookups: cannot write " + json_path);
    }
    return mismatches == 0 && pcf_mismatches == 0 && filtered_mismatches == 0 && render_mismatches == 0 ? 0 : 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_client_lookups: %s\n", e.what());
    return 1;
  }
}
