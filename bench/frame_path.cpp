// Engine mode's frame path alone (GpuMap::retire + record_uploads + record_end_of_frame on
// the host), replayed many times from a camera path over a real pack, so a few microseconds
// show through the noise of a shared machine.
//
// Each scene's pack is read directly (no server, no socket, no fetch thread): a camera's
// window of finest texels sweeps the map (boustrophedon over a grid of windows, round and
// round); between frames, untimed, the tiles the window needs are taken from the client's
// request queue, --arriving at a time, and delivered to a client RemoteMap exactly as the
// fetcher does (RemoteMap::tile_arrived: CRC, inflate, a slot of the TileCache, the change
// journal). With --cache-fraction < 1 the cache holds that share of the pack's tiles, so
// arrivals evict (the LRU slots come back with other tiles: unlink + link); with 1 it holds
// them all and a pass ends when the map is resident (a new RemoteMap and GpuMap then, untimed).
// Then the frame's three calls are timed on the host around a real command buffer of a
// Vulkan device (an engine's own: the rasterizer's instance and device set-up,
// examples/raster/engine_device.hpp, then this file's command buffers and fences; GpuMap gets
// an EngineDevice), which is submitted and waited for, untimed.
// Before each timed frame --flush-mib MiB of other memory are written, as an engine's frame
// (and the fetch thread's inflate) leaves the caches cold for the frame path (0: warm).
//
// Figures: per frame with arrivals, host time of the three calls (and record_uploads alone),
// median / p10 / p90 / p99 / min; hardware counters of the same span from perf_event_open
// (instructions, cache misses, dTLB read misses) where the kernel and the machine allow,
// else software ones (task clock, page faults, context switches), else none ("-"); and the
// percentiles over the frames with no context switch inside the span (a loaded machine's
// preemptions, not the frame path's cost; their count is printed). Beside the wall time, the
// calling thread's CPU time over the same span (CLOCK_THREAD_CPUTIME_ID, read just outside
// it: a preemption inside the span does not count; on a VM whose syscalls cost ~10 us the
// reads stay out of the wall span, and their own CPU share is a constant ~1-3 us). A digest
// of every frame's upload figures (slots, tile bytes, page-table bytes) says whether two
// builds did the same work frame for frame.
//
//   bench_frame_path [--packs P1,P2] [--scenes procedural:city,FILE] [--res 4k] [--tile-bytes 1024]
//                    [--out bench-out/raster] [--frames 1000] [--arriving 100] [--cache-fraction 0.5]
//                    [--flush-mib 32] [--claims 0] [--device llvmpipe] [--json PATH]
//
// --claims N: the feedback readback exercised as a shadow pass would leave it (the bench
// records none): each timed frame's feedback buffer gets N claims written by the device
// (vkCmdUpdateBuffer after record_end_of_frame, untimed) the way st_feedback (st_eval.glsl)
// lays them out: absent skip-grid entries (key e + 1 at level K, hashed and probed as the
// shader does), a rotating run of the grid's tile and index entries. The next frame's
// retire reads them (GpuMap's collect_feedback: claims into the client's wanted queue), so
// retire's time grows by their cost, and the arrivals follow the claims too (another
// digest than --claims 0). Default 0: no claims, as before.
//
// Packs: --packs names built packs; else each --scenes entry's pack in --out under
// bench_raster's name (SCENE_RES_dagmh_tBYTES.pack), built there if absent. Defaults: the
// procedural city and Debian's assimp model 2CylinderEngine.glb (a real open mesh), 4K
// maps of 1 KiB tiles, as bench_raster's frame-path figures. 1080p does not enter: the
// frame path's host work depends on the tiles arriving, not on the resolution.
#include <linux/perf_event.h>
#include <sys/ioctl.h>
#include <sys/syscall.h>
#include <unistd.h>
#include <vulkan/vulkan.h>

#include <algorithm>
#include <bit>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "bench/options.hpp"
#include "bench/bench_map.hpp"
#include "bench/timing.hpp"
#include "examples/raster/engine_device.hpp"
#include "client/map_access.hpp"
#include "client/remote_map.hpp"
#include "gpu/layout.hpp"
#include "shadowtile/gpu.hpp"
#include "scene/scene_limits.hpp"
#include "shadowtile/vk_setup.hpp"
#include "tiles/bake/map_build.hpp"
#include "tiles/core/pack_reader.hpp"

namespace {

using namespace st;
using namespace st::bench;
using Clock = std::chrono::steady_clock;
volatile uint8_t flush_sink = 0;  // keeps the cache flush between frames

constexpr uint32_t kFeedbackCapacity = 1024;  // GpuOptions::feedback_capacity here

struct Args {
  std::string packs, scenes = "procedural:city,/usr/share/assimp/models/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb";
  std::string light = "sun:azimuth=30,elevation=50", res = "4k", out = "bench-out/raster", device = "llvmpipe", json;
  uint32_t tile_bytes = 1024, frames = 1000, arriving = 100, flush_mib = 32, claims = 0;
  double cache_fraction = 0.5;
  SceneLimits limits;
};

Args parse_args(int argc, char** argv) {
  Args a;
  Options opt("bench_frame_path", "Engine mode's frame path alone on the engine's Vulkan device");
  opt.value("--packs", a.packs, "Packs already built, comma-separated (instead of --scenes)")
      .value("--scenes", a.scenes, "Scene specs, comma-separated")
      .value("--light", a.light, "Light spec")
      .value("--res", a.res, "Map side")
      .value("--tile-bytes", a.tile_bytes, "Tile budget in bytes")
      .value("--out", a.out, "Folder for the packs built")
      .value("--frames", a.frames, "Frames timed (> 0)")
      .value("--arriving", a.arriving, "Tiles arriving per frame (> 0)")
      .value("--cache-fraction", a.cache_fraction, "The GPU tile cache as a fraction of the map's tiles, in (0, 1]")
      .value("--flush-mib", a.flush_mib, "MiB written between frames to flush the CPU caches")
      .value("--claims", a.claims, "Feedback claims written into each frame's feedback buffer (0..512)")
      .value("--device", a.device, "Vulkan device (by name)")
      .value("--json", a.json, "Write the rows as JSON to PATH [bench-out/frame_path.json]")
      .with("--scene-limits", [&](const std::string& v) { a.limits = parse_scene_limits(v, a.limits); },
            "What reading a scene file may cost, KEY=VALUE[,...] (scene/scene_limits.hpp)");
  opt.parse(argc, argv);
  if (a.frames == 0 || a.arriving == 0) throw Error("bench_frame_path: --frames and --arriving must be > 0");
  if (a.claims > kFeedbackCapacity / 2) throw Error("bench_frame_path: --claims must be at most " + std::to_string(kFeedbackCapacity / 2));
  if (!(a.cache_fraction > 0 && a.cache_fraction <= 1)) throw Error("bench_frame_path: --cache-fraction must be in (0, 1]");
  if (a.json.empty()) a.json = "bench-out/frame_path.json";
  return a;
}

std::string short_name(const std::string& scene) {
  const std::string base = std::filesystem::path(scene).stem().string();
  std::string s = scene.rfind("procedural:", 0) == 0 ? scene.substr(11) : base;
  for (char& c : s)
    if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
  return s;
}

void vk_ok(VkResult r, const char* what) {
  if (r != VK_SUCCESS) throw Error(std::string("bench_frame_path: ") + what + " failed: " + std::to_string(int(r)));
}

// What a game's renderer owns: instance, device, one queue (the engine's device of
// examples/raster/engine_device.hpp: a compute queue, no layers, since validation would time
// itself), a command buffer and fence per frame in flight.
struct Engine {
  raster::VulkanDevice dev;
  VkDevice device = VK_NULL_HANDLE;
  VkQueue queue = VK_NULL_HANDLE;
  VkCommandPool pool = VK_NULL_HANDLE;
  std::vector<VkCommandBuffer> cmds;
  std::vector<VkFence> fences;
  const std::string& name = dev.name;

  static raster::EngineDeviceOptions options(const std::string& want) {
    raster::EngineDeviceOptions o;
    o.device = want, o.graphics = false, o.app_name.clear();
    return o;
  }
  Engine(const std::string& want, uint32_t frames_in_flight)
      : dev(options(want)), device(dev.device), queue(dev.queue) {
    const vk_setup::Device<vk_setup::Loader> v{vk_setup::kLoader, device};
    pool = vk_setup::command_pool(v, dev.family, true);
    cmds.resize(frames_in_flight);
    vk_setup::command_buffers(v, pool, cmds);
    for (uint32_t i = 0; i < frames_in_flight; ++i) fences.push_back(vk_setup::fence(v, false));
  }
  ~Engine() {
    vkDeviceWaitIdle(device);
    for (VkFence f : fences) vkDestroyFence(device, f, nullptr);
    if (pool) vkDestroyCommandPool(device, pool, nullptr);
  }
  Engine(const Engine&) = delete;
  Engine& operator=(const Engine&) = delete;

  gpu::EngineDevice engine_device() const { return dev.engine_device(); }
  VkCommandBuffer begin(uint64_t frame) {
    VkCommandBuffer c = cmds[frame % cmds.size()];
    vk_ok(vkResetCommandBuffer(c, 0), "vkResetCommandBuffer");
    VkCommandBufferBeginInfo bi{};
    bi.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO;
    bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
    vk_ok(vkBeginCommandBuffer(c, &bi), "vkBeginCommandBuffer");
    return c;
  }
  // Submits frame's buffer and waits for it (the next frame then finds the device idle).
  void submit_and_wait(uint64_t frame) {
    VkCommandBuffer c = cmds[frame % cmds.size()];
    VkFence f = fences[frame % fences.size()];
    vk_ok(vkEndCommandBuffer(c), "vkEndCommandBuffer");
    VkSubmitInfo si{};
    si.sType = VK_STRUCTURE_TYPE_SUBMIT_INFO;
    si.commandBufferCount = 1;
    si.pCommandBuffers = &c;
    vk_ok(vkQueueSubmit(queue, 1, &si, f), "vkQueueSubmit");
    vk_ok(vkWaitForFences(device, 1, &f, VK_TRUE, UINT64_MAX), "vkWaitForFences");
    vk_ok(vkResetFences(device, 1, &f), "vkResetFences");
  }
};

// Counters of this thread over the timed span (perf_event_open), each opened on its own
// so one the machine lacks (a VM without a PMU) leaves the others.
struct Counters {
  struct One {
    const char* name;
    uint32_t type;
    uint64_t config;
    int fd = -1;
  };
  std::vector<One> all = {
      {"instructions", PERF_TYPE_HARDWARE, PERF_COUNT_HW_INSTRUCTIONS},
      {"cache_misses", PERF_TYPE_HARDWARE, PERF_COUNT_HW_CACHE_MISSES},
      {"dtlb_read_misses", PERF_TYPE_HW_CACHE,
       PERF_COUNT_HW_CACHE_DTLB | (PERF_COUNT_HW_CACHE_OP_READ << 8) | (PERF_COUNT_HW_CACHE_RESULT_MISS << 16)},
      {"task_clock_ns", PERF_TYPE_SOFTWARE, PERF_COUNT_SW_TASK_CLOCK},
      {"page_faults", PERF_TYPE_SOFTWARE, PERF_COUNT_SW_PAGE_FAULTS},
      {"context_switches", PERF_TYPE_SOFTWARE, PERF_COUNT_SW_CONTEXT_SWITCHES},
  };
  Counters() {
    for (One& c : all) {
      perf_event_attr at{};
      at.size = sizeof at;
      at.type = c.type;
      at.config = c.config;
      at.exclude_kernel = c.type != PERF_TYPE_SOFTWARE;
      at.exclude_hv = 1;
      c.fd = int(syscall(SYS_perf_event_open, &at, 0, -1, -1, 0));
    }
  }
  ~Counters() {
    for (One& c : all)
      if (c.fd >= 0) close(c.fd);
  }
  Counters(const Counters&) = delete;
  Counters& operator=(const Counters&) = delete;
  void read_all(std::vector<int64_t>& out) const {
    out.assign(all.size(), -1);
    for (size_t i = 0; i < all.size(); ++i) {
      uint64_t v = 0;
      if (all[i].fd >= 0 && ::read(all[i].fd, &v, sizeof v) == ssize_t(sizeof v)) out[i] = int64_t(v);
    }
  }
};

// A feedback buffer as a shadow pass leaves it with `n` claims (st_feedback's layout,
// st_layout.h): absent skip-grid entries, starting at entry *next of the grid's non-constant
// ones (round and round), key e + 1, hashed into the key set and probed as the shader does.
// Empty when the grid has no such entry.
void fake_claims(const CutGrid& grid, uint32_t n, uint32_t& next, std::vector<uint32_t>& fb) {
  namespace L = gpu::layout;
  const uint32_t cap = kFeedbackCapacity;
  fb.assign(L::kFbHeaderWords + size_t(cap) * (2 + L::kFbRecordWords), 0u);
  fb[L::kFbCapacity] = cap;
  const uint32_t entries = uint32_t(grid.entries.size()), k = grid.levels;
  uint32_t used = 0;
  for (uint32_t tried = 0; used < n && tried < entries; ++tried, next = (next + 1) % entries) {
    const GridEntry& g = grid.entries[next];
    if (g.kind == EntryKind::constant) continue;
    const uint32_t key = next + 1;
    uint32_t h = (key * 0x9E3779B1u) & (cap - 1);
    while (fb[L::kFbHeaderWords + h] != 0) h = (h + 1) & (cap - 1);  // n <= cap / 2: ends
    fb[L::kFbHeaderWords + h] = key;
    uint32_t* rec = fb.data() + L::kFbHeaderWords + cap + size_t(h) * L::kFbRecordWords;
    rec[L::kFbRecLevel] = k;
    rec[L::kFbRecX] = next & ((1u << k) - 1);
    rec[L::kFbRecY] = next >> k;
    rec[L::kFbRecValue] = std::bit_cast<uint32_t>(g.value);
    rec[L::kFbRecKind] = uint32_t(g.kind) | uint32_t(g.index_levels) << 8;
    rec[L::kFbRecCount] = 1 + used % 7;
    fb[L::kFbHeaderWords + size_t(cap) * (1 + L::kFbRecordWords) + used] = h;
    fb[L::kFbAbsentTaps] += rec[L::kFbRecCount];
    ++used;
  }
  fb[L::kFbUsed] = used;
  fb[L::kFbHoles] = used;
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const double r = p * double(v.size() - 1);
  const size_t i = size_t(r);
  const double f = r - double(i);
  return i + 1 < v.size() ? v[i] * (1 - f) + v[i + 1] * f : v[i];
}

struct FrameRow {
  double host_us, uploads_us, retire_us, end_us, cpu_us;
  uint32_t slots;
  uint64_t tile_bytes, page_bytes;
  std::vector<int64_t> counts;  // per Counters::all, -1 unavailable
};

// The camera's window of finest texels: position p of a boustrophedon walk over a grid x grid
// tiling of the map (round and round).
struct CameraPath {
  uint32_t grid = 8;
  uint64_t side = 0, step = 0, position = 0;
  uint64_t x() const {
    const uint64_t row = (position / grid) % grid, col = position % grid;
    return (row % 2 ? grid - 1 - col : col) * step;
  }
  uint64_t y() const { return ((position / grid) % grid) * step; }
};

std::string pack_for(const Args& a, const std::string& spec) {
  const uint32_t level = parse_level(a.res);
  const std::string path = a.out + "/" + short_name(spec) + "_" + side_name(level) + "_dagmh_t" + std::to_string(a.tile_bytes) + ".pack";
  if (std::filesystem::exists(path)) return path;
  std::filesystem::create_directories(a.out);
  const Scene scene = load_scene(spec, {}, a.limits);
  const LightSpace light = LightSpace::fit(LightSpec::parse(a.light), scene.bounds());
  MapBuildOptions o;
  o.map_level = level;
  o.encoding = parse_encoding("dagmh");
  o.tile_bytes = a.tile_bytes;
  o.scene_spec = spec;
  o.light_spec = a.light;
  o.dagmh_dictionary = o.dagmh_mixed_tiles = true;  // the CLI's defaults (as bench_raster)
  std::fprintf(stderr, "bench_frame_path: building %s\n", path.c_str());
  build_map(scene, light, o, path);
  return path;
}

}  // namespace

int main(int argc, char** argv) try {
  const Args a = parse_args(argc, argv);
  std::vector<std::pair<std::string, std::string>> packs;  // (row name, path)
  if (!a.packs.empty()) {
    for (const std::string& p : split_list(a.packs)) packs.push_back({std::filesystem::path(p).stem().string(), p});
  } else {
    for (const std::string& s : split_list(a.scenes)) packs.push_back({short_name(s), pack_for(a, s)});
  }
  constexpr uint32_t kFramesInFlight = 2;
  Engine engine(a.device, kFramesInFlight);
  Counters counters;
  std::vector<uint8_t> flush(size_t(a.flush_mib) << 20, 1);
  nlohmann::json rows = nlohmann::json::array();
  std::vector<std::string> lines;
  std::string counter_names;
  for (const Counters::One& c : counters.all)
    if (c.fd >= 0) counter_names += std::string(counter_names.empty() ? "" : ", ") + c.name;
  for (const auto& [row_name, path] : packs) {
    const std::shared_ptr<PackReader> reader = PackReader::open(path);
    const uint64_t tiles = reader->tiles().size();
    const uint32_t L = reader->map_level();
    const uint32_t slots = uint32_t(std::max<double>(a.arriving * 2.0, std::ceil(double(tiles) * a.cache_fraction))) +
                           (a.cache_fraction >= 1 ? 8u : 0u);
    std::vector<FrameRow> got;
    uint64_t digest = 1469598103934665603ull;  // FNV-1a over every timed frame's upload figures
    auto mix = [&](uint64_t v) {
      for (int i = 0; i < 8; ++i) digest = (digest ^ ((v >> (8 * i)) & 0xFF)) * 1099511628211ull;
    };
    uint64_t frame = 100, evictions_guess = 0, passes = 0;
    std::vector<int64_t> c0, c1;
    std::vector<uint32_t> claim_words;
    uint32_t claim_next = 0;
    uint64_t claims_read = 0;
    std::vector<proto::TileRequest> want;
    const auto t_scene = Clock::now();
    while (got.size() < a.frames) {
      ++passes;
      client::ClientOptions co;
      co.cache_slots = slots;
      co.want_capacity = uint32_t(tiles + 16);
      co.max_slot_bytes = 1u << 30;
      const auto h = reader->header_bytes();
      const auto g = reader->grid_bytes();
      auto remote = std::make_shared<client::RemoteMap>(row_name, std::vector<uint8_t>(h.begin(), h.end()),
                                                        std::vector<uint8_t>(g.begin(), g.end()), co,
                                                        std::make_shared<client::Notifier>());
      gpu::GpuOptions go;
      go.frames_in_flight = kFramesInFlight;
      go.feedback_capacity = kFeedbackCapacity;
      gpu::GpuMap gm(client::MapAccess::wrap(remote), engine.engine_device(), go);
      // The first frame sends the whole page table: untimed.
      {
        VkCommandBuffer c = engine.begin(frame);
        gm.retire(frame - 1);
        gm.record_uploads(c, frame);
        gm.record_end_of_frame(c, frame);
        engine.submit_and_wait(frame);
        ++frame;
      }
      CameraPath cam;
      cam.side = uint64_t(1) << L;
      cam.step = std::max<uint64_t>(1, cam.side / cam.grid);
      uint32_t request_id = 1, empty_windows = 0;
      const uint64_t last_position = a.cache_fraction >= 1 ? cam.grid * cam.grid : ~uint64_t(0);
      remote->request_region(L, cam.x(), cam.y(), cam.step, cam.step, 100);
      while (got.size() < a.frames && cam.position < last_position) {
        // Untimed: this frame's arrivals, as the fetcher delivers them.
        want.clear();
        while (want.size() < a.arriving && cam.position < last_position) {
          remote->take_wanted(a.arriving - want.size(), request_id, want);
          if (want.size() < a.arriving) {
            ++cam.position;
            if (++empty_windows > 4 * cam.grid * cam.grid) break;  // nothing left to fetch anywhere
            remote->cancel_outside(L, cam.x(), cam.y(), cam.step, cam.step);
            remote->request_region(L, cam.x(), cam.y(), cam.step, cam.step, 100);
          } else {
            empty_windows = 0;
          }
        }
        if (want.empty()) break;
        for (const proto::TileRequest& t : want) {
          const TileIndexEntry e = *reader->find(t.tile_id);
          proto::TileMeta meta;
          meta.tile_id = t.tile_id;
          meta.flags = proto::kTileFlagZlib;
          meta.uncompressed_size = e.raw_size;
          meta.payload_crc32 = e.crc;
          remote->tile_arrived(meta, request_id, reader->read_stored(t.tile_id));
        }
        ++request_id;
        for (size_t i = 0; i < flush.size(); i += 64) flush[i] = uint8_t(flush[i] + 1);
        if (!flush.empty()) flush_sink = flush_sink + flush[flush.size() / 2];
        VkCommandBuffer c = engine.begin(frame);
        counters.read_all(c0);
        const double cpu0 = thread_cpu_now();
        const auto t0 = Clock::now();
        const std::span<const gpu::FrameStats> done = gm.retire(frame - 1);
        const auto t1 = Clock::now();
        for (const gpu::FrameStats& d : done) claims_read += d.feedback_tiles;
        const gpu::FrameStats fs = gm.record_uploads(c, frame);
        const auto t2 = Clock::now();
        gm.record_end_of_frame(c, frame);
        const auto t3 = Clock::now();
        const double cpu1 = thread_cpu_now();
        counters.read_all(c1);
        if (a.claims > 0) {  // what a shadow pass would have claimed: read by the next frame's retire
          fake_claims(remote->grid(), a.claims, claim_next, claim_words);
          const gpu::GpuDescriptors d = gm.descriptors(frame);
          const VkDeviceSize bytes = std::min<VkDeviceSize>(claim_words.size() * 4, 65536);
          vkCmdUpdateBuffer(c, d.feedback.buffer, 0, bytes, claim_words.data());
          VkMemoryBarrier mb{};
          mb.sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER;
          mb.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
          mb.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
          vkCmdPipelineBarrier(c, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_HOST_BIT, 0, 1, &mb, 0, nullptr, 0, nullptr);
        }
        engine.submit_and_wait(frame);
        ++frame;
        if (fs.slots_uploaded == 0) continue;
        auto us = [](Clock::time_point x, Clock::time_point y) { return std::chrono::duration<double, std::micro>(y - x).count(); };
        FrameRow r{us(t0, t3), us(t1, t2), us(t0, t1), us(t2, t3), (cpu1 - cpu0) * 1e6, fs.slots_uploaded, fs.tile_bytes, fs.page_bytes, {}};
        for (size_t i = 0; i < c0.size(); ++i) r.counts.push_back(c0[i] < 0 || c1[i] < 0 ? -1 : c1[i] - c0[i]);
        mix(fs.slots_uploaded), mix(fs.tile_bytes), mix(fs.page_bytes);
        got.push_back(std::move(r));
      }
      // Uploads beyond the slot count went into slots used before in this pass (evictions).
      evictions_guess += gm.stats().slots_uploaded > slots ? gm.stats().slots_uploaded - slots : 0;
      if (got.empty() && passes > 1) throw Error("bench_frame_path: " + path + ": no tile arrived (an empty map?)");
    }
    std::vector<double> host, up, ret, ntiles, tile_b, page_b, quiet, cpu, quiet_cpu;
    size_t switched = 0;  // frames with a context switch inside the span (the machine's, not ours)
    const size_t csw = 5;  // Counters::all's context_switches
    for (const FrameRow& r : got) {
      host.push_back(r.host_us), up.push_back(r.uploads_us), ret.push_back(r.retire_us), cpu.push_back(r.cpu_us);
      ntiles.push_back(r.slots), tile_b.push_back(double(r.tile_bytes)), page_b.push_back(double(r.page_bytes));
      if (r.counts.size() > csw && r.counts[csw] > 0) ++switched;
      else quiet.push_back(r.host_us), quiet_cpu.push_back(r.cpu_us);
    }
    nlohmann::json row = {{"scene", row_name}, {"pack", path}, {"tiles", tiles}, {"cache_slots", slots},
                          {"frames", got.size()}, {"passes", passes}, {"slot_reuses", evictions_guess},
                          {"tiles_per_frame_median", median(ntiles)}, {"tile_bytes_per_frame_median", median(tile_b)},
                          {"page_bytes_per_frame_median", median(page_b)}, {"frames_context_switched", switched}, {"upload_digest", digest},
                          {"claims_per_frame", a.claims}, {"claims_read", claims_read},
                          {"seconds", std::chrono::duration<double>(Clock::now() - t_scene).count()}};
    for (const char* p : {"min", "p10", "median", "p90", "p99"}) {
      const double q = p == std::string("min") ? 0.0 : p == std::string("p10") ? 0.1 : p == std::string("median") ? 0.5 : p == std::string("p90") ? 0.9 : 0.99;
      row[std::string("host_us_") + p] = percentile(host, q);
      row[std::string("record_uploads_us_") + p] = percentile(up, q);
      row[std::string("host_us_unswitched_") + p] = percentile(quiet, q);
      row[std::string("cpu_us_") + p] = percentile(cpu, q);
      row[std::string("cpu_us_unswitched_") + p] = percentile(quiet_cpu, q);
    }
    row["retire_us_median"] = percentile(ret, 0.5);
    row["retire_us_p90"] = percentile(ret, 0.9);
    std::string counter_cells;
    for (size_t i = 0; i < counters.all.size(); ++i) {
      std::vector<double> v;
      for (const FrameRow& r : got)
        if (r.counts[i] >= 0) v.push_back(double(r.counts[i]));
      if (v.size() != got.size() || v.empty()) continue;
      row[std::string(counters.all[i].name) + "_median"] = percentile(v, 0.5);
      row[std::string(counters.all[i].name) + "_p10"] = percentile(v, 0.1);
      char cell[64];
      std::snprintf(cell, sizeof cell, " %s %.0f", counters.all[i].name, percentile(v, 0.5));
      counter_cells += cell;
    }
    row["host_us"] = host;
    row["cpu_us"] = cpu;
    rows.push_back(row);
    char line[512];
    std::snprintf(line, sizeof line, "%-30s %6llu %6u %6zu %5.0f %8.0f %6.0f | %6.1f %6.1f %6.1f %6.1f %6.1f | %6.1f %6.1f | %016llx",
                  row_name.c_str(), (unsigned long long)tiles, slots, got.size(), median(ntiles), median(tile_b),
                  median(page_b), percentile(host, 0), percentile(host, 0.1), percentile(host, 0.5), percentile(host, 0.9),
                  percentile(host, 0.99), percentile(up, 0.1), percentile(up, 0.5), (unsigned long long)digest);
    char quiet_line[512];
    std::snprintf(quiet_line, sizeof quiet_line,
                  "%32s%zu frames with a context switch; the others: median %.1f p90 %.1f p99 %.1f; thread CPU median %.1f p90 %.1f p99 %.1f\n"
                  "%32sretire median %.1f p90 %.1f (claims read %llu)",
                  "", switched, percentile(quiet, 0.5), percentile(quiet, 0.9), percentile(quiet, 0.99), percentile(quiet_cpu, 0.5),
                  percentile(quiet_cpu, 0.9), percentile(quiet_cpu, 0.99), "", percentile(ret, 0.5), percentile(ret, 0.9),
                  (unsigned long long)claims_read);
    lines.push_back(std::string(line) + "\n" + quiet_line +
                    (counter_cells.empty() ? "" : "\n" + std::string(32, ' ') + "counters (median):" + counter_cells));
    std::fprintf(stderr, "bench_frame_path: %s done\n", row_name.c_str());
  }
  std::printf("device '%s', %u frames per scene, %u tiles arriving per frame, cache %.2f of the tiles, %u MiB flushed before each frame\n",
              engine.name.c_str(), a.frames, a.arriving, a.cache_fraction, a.flush_mib);
  std::printf("host us = retire + record_uploads + record_end_of_frame; frames that uploaded tiles; load average %.1f\n",
              load_average());
  std::printf("counters available: %s\n", counter_names.empty() ? "none (perf_event_open refused)" : counter_names.c_str());
  std::printf("%-30s %6s %6s %6s %5s %8s %6s | %6s %6s %6s %6s %6s | %6s %6s | %s\n", "scene", "tiles", "slots", "frames",
              "tiles", "tile B", "page B", "min", "p10", "median", "p90", "p99", "up p10", "up med", "upload digest");
  for (const std::string& l : lines) std::printf("%s\n", l.c_str());
  nlohmann::json report = {{"device", engine.name}, {"frames", a.frames}, {"arriving", a.arriving},
                           {"cache_fraction", a.cache_fraction}, {"flush_mib", a.flush_mib},
                           {"load_average", load_average()}, {"rows", rows}};
  if (const auto dir = std::filesystem::path(a.json).parent_path(); !dir.empty()) std::filesystem::create_directories(dir);
  std::ofstream(a.json) << report.dump(1) << "\n";
  std::printf("wrote %s\n", a.json.c_str());
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "bench_frame_path: %s\n", e.what());
  return 1;
}
