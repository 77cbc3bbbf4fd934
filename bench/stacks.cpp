// Shadow-map stacks (MH 2016 §4, Tables 4-5) side by side with N independent 2D MH
// quadtrees of the same samples: bytes, build time, and lookup time per slice, per
// time-interpolated lookup and per soft-shadow sample.
//
//   bench_stacks [--res 256] [--city-samples 32] [--hair-samples 64] [--lookups 20000]
//                [--reps 3] [--case city|city-hour|hairball|all] [--hair-jitter 0.5] [--json PATH]
//                [--mode auto|whole|blocked] [--tracer auto|embree] [--spill-dir /tmp]
//                [--frame ground|ortho|both] [--hair-frame window|translate|both] [--all-2d]
//                [--oct-merge on|off] [--stack-cells octree|slices|smaller] [--split-cells]
//                [--profile-soft N]
//
// --all-2d (whole mode): every slice also encoded as MMH and DAG-MH, the smaller 2D
// encodings, so the octree is set against the best of them too ("best 2D" line). Every
// whole-mode run also prints the encoder's stats (shared blocks, far words: format version 3), the
// sharing measure with the roundest values, and the cost model of anisotropic splits
// (mh_octree_share.hpp `hybrid_octree_quad_words`, "hybrid model" line).
//
// --oct-merge on: the whole-stack octree with the encoder's subtree merger (off by
// default, as in the encoder: it saved under 0.1%; MHOCT.md "Version 3, merged subtrees
// measured"); the "merge" line gives the merger's counts.
//
// --stack-cells (blocked mode): the cells' form (tiles/core/stack_slices.hpp): octree (the
// default here, the earlier figures), slices, or smaller (what `build` writes by default).
// --split-cells (blocked mode): a cell over 64 KiB is split below K (what `build` does by
// default) rather than the whole cut moving deeper.
//
// --profile-soft N (blocked mode): after the timings, N more passes of the single soft
// lookups over the same points, so that `perf record` over the whole run (minutes of
// tracing and the cut) catches the lookups: a profile of the soft lookups alone. The
// blocked rows also time the soft lookup over 32 points cycled ("cache-hot": their tiles'
// lines stay cached), the compute floor beside the cold figure.
//
// --frame: the sun paths' frame (light_set.hpp "Frames"): ground (the default, the
// oblique ground-aligned frame), ortho (an orthographic box per sample), or both (each
// sun case twice in one run, ortho first, for side-by-side ratios). --hair-frame: the
// area light's frame, window (the default) or translate, or both.
//
// --mode whole (the default below 4K^2 per slice) holds the stack in memory and builds
// one octree buffer; --mode blocked (from 4K^2) spills and builds the pack's cut out of
// core (run_case_blocked below). Peak RSS is printed (getrusage).
//
// Cases: procedural:city under a day's sun path (azimuth 100..260, elevation 25..65), the
// same city under an hour of it (azimuth 170..185, elevation 50..52), and
// procedural:hairball under a 4 m x 4 m area light 25 m above it (Hilbert-ordered,
// jitter 0.5) in the area light's window frame (light_set.hpp "Frames"; --hair-frame
// translate: the translated spots of before, both: the two cases side by side in one run,
// "hairball" and "hairball-translate"). Each slice is traced by trace_stack (the light-space rasterizer for sun
// samples, Embree for the area light's; --tracer embree: Embree for all), then
//   octree: build_octree + encode_octree of the whole stack;
//   2D:     build_hierarchy + encode_mh of every slice (what N separate packs would hold).
// Lookups run on receivers that lie on visible surfaces of sample 0 (its depth map's first
// hits, nudged 1e-4 towards the light), in one loop per kind over the same points:
//   2D lit       : project into slice w's light, MH evaluator lit test (w random)
//   octree lit   : StackLookup::lit(p, w), the same points and slices
//   time interp. : StackLookup::visibility(p, t), t random (two slices blended)
//   soft shared  : StackLookup::soft_visibility(p) (one shared walk for all N samples)
//   soft batched : StackLookup::soft_visibility(points, out) over the same points, the
//                  shared walks of kWalkLanes points interleaved (walk_interleave.hpp);
//                  both soft lookups again over 32 points cycled (cache-hot: the floor
//                  without memory stalls), and the batched walks' prefetches per sample
//   soft bounded : StackLookup::soft_visibility_bounded(p) (each walk stops where the
//                  node's value bounds decide it; StackBounds made once, timed apart)
//   soft indep.  : StackLookup::soft_visibility_independent(p) (N octree walks)
//   soft 2D      : N 2D evaluator lit tests (N separate quadtrees)
// The "soft walk" line sums the soft lookups up per sample and against the 2D lookup, with
// two figures of the walks themselves (JSON soft_same_texel_share, soft_bounds_levels_early):
// the share of consecutive samples on the same texel and how many levels above a walk's
// end per-node bounds would decide a sample.
// Times are medians over --reps rounds of thread CPU time per lookup, every kind timed once
// per round in turn (side by side: the machine's load falls on all alike); the table also
// gives each against the 2D single lookup measured in the same rounds.
#include <sys/resource.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <ctime>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "bench/options.hpp"
#include "common/error.hpp"
#include "common/hash.hpp"
#include "tiles/bake/depth_bounds.hpp"
#include "scene/scene.hpp"
#include "tiles/bake/stack_build.hpp"
#include "tiles/encode/stack_blocked.hpp"
#include "tiles/encode/stack_pack.hpp"
#include "tiles/core/stack_map.hpp"
#include "tiles/encode/encode.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/encode/mh_octree_encode.hpp"
#include "tiles/encode/mh_octree_share.hpp"
#include "tiles/core/encoding.hpp"
#include "tiles/core/resolution.hpp"
#include "tiles/core/stack_lookup.hpp"
#include "bench/timing.hpp"

namespace {

// The world point just in front of the first surface `lo` of texel (x, y) of light `ls`:
// a receiver on that surface, lit in that slice.
st::Vec3d receiver_point(const st::LightSpace& ls, uint32_t level, uint64_t x, uint64_t y, float lo) {
  const st::LightRay ray = ls.texel_ray(level, x, y);
  const double d = std::max(0.0, double(lo) - 1e-4);
  const double t = ls.parallel() ? d : ls.near_plane() + d * (ls.far_plane() - ls.near_plane());
  return ray.origin + ray.dir * t;
}

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// Lookup kinds timed side by side (thread CPU time per lookup, bench/timing.hpp).
using st::bench::SideBySide;

volatile float g_sink = 0;
bool g_all_2d = false;  // --all-2d
bool g_oct_merge = false;  // --oct-merge
st::StackCells g_stack_cells = st::StackCells::octree;  // --stack-cells (blocked mode)
std::string g_stack_cells_name = "octree";
bool g_split_cells = false;  // --split-cells (blocked mode): cells over 64 KiB split below K
size_t g_profile_soft = 0;    // --profile-soft (blocked mode): extra passes of the soft lookups

double peak_rss_mib() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return double(ru.ru_maxrss) / 1024.0;
}

struct Case {
  std::string name, scene, light;
};

nlohmann::json run_case(const Case& c, uint32_t level, size_t lookups, int reps, bool embree_only) {
  std::printf("\n== %s: %s, %s, %u^2 per slice\n", c.name.c_str(), c.scene.c_str(), c.light.c_str(), 1u << level);
  std::fflush(stdout);
  const st::Scene scene = st::load_scene(c.scene);
  const st::LightSet set = st::fit_light_set(scene, st::LightSetSpec::parse(c.light));
  std::printf("fitted light set: %s\n", set.spec.to_string().c_str());
  std::printf("map square (slice 0): %.1f m a side, a texel %.3f m; frame %s\n", set.samples[0].extent_uv(),
              set.samples[0].extent_uv() / double(uint64_t(1) << level), st::light_kind_name(set.samples[0].kind()));
  const uint32_t n = set.size();
  const uint32_t side = 1u << level;

  // Trace every slice.
  auto t0 = Clock::now();
  st::IntervalStack stack{level, n, {}};
  if (embree_only) {
    stack.data.reserve(size_t(side) * side * n);
    for (uint32_t w = 0; w < n; ++w) {
      st::DepthBoundsTracer tracer(scene, set.samples[w]);
      const st::IntervalTile t = tracer.trace({level, 0, 0, side, side});
      stack.data.insert(stack.data.end(), t.data.begin(), t.data.end());
    }
  } else {
    stack = st::trace_stack(scene, set, level);  // the rasterizer for sun samples
  }
  const double trace_s = since(t0);

  // The octree.
  t0 = Clock::now();
  const st::OctHierarchy oh = st::build_octree(stack);
  const double oct_build_s = since(t0);
  t0 = Clock::now();
  st::OctEncodeStats oct_stats;
  st::OctEncodeOptions oct_options;
  oct_options.merge = g_oct_merge;
  const std::vector<uint8_t> oct = st::encode_octree(oh, &oct_stats, oct_options);
  const double oct_encode_s = since(t0);
  t0 = Clock::now();
  const st::OctreeSharing share = st::measure_octree_sharing(oh);
  const double share_s = since(t0);

  // N independent quadtrees (with --all-2d also N MMH and N DAG-MH buffers: the best 2D
  // encoding of the same slices).
  std::vector<std::vector<uint8_t>> mh(n);
  std::vector<st::QuadSubtreeWords> quad_words(n);
  size_t mh_bytes = 0, mh_nodes = 0, mmh_bytes = 0, dagmh_bytes = 0;
  double mh_build_s = 0, mh_encode_s = 0;
  for (uint32_t w = 0; w < n; ++w) {
    st::IntervalTile tile;
    tile.level = level;
    tile.width = tile.height = side;
    tile.data.assign(stack.data.begin() + ptrdiff_t(size_t(w) * side * side),
                     stack.data.begin() + ptrdiff_t(size_t(w + 1) * side * side));
    t0 = Clock::now();
    const st::Hierarchy h = st::build_hierarchy(tile);
    mh_build_s += since(t0);
    t0 = Clock::now();
    mh[w] = st::encode_mh(h);
    mh_encode_s += since(t0);
    mh_bytes += mh[w].size();
    mh_nodes += h.node_count();
    if (g_all_2d) mmh_bytes += st::encode_mmh(h).size(), dagmh_bytes += st::encode_dagmh(h).size();
    // Per node: its subtree's words (STOC / MH quadtree sizes), for the hybrid cost model.
    const auto first = h.first_child_index();
    std::vector<std::vector<uint32_t>> sub(h.levels.size());
    for (size_t l = h.levels.size(); l-- > 0;) {
      sub[l].resize(h.levels[l].size());
      for (size_t j = 0; j < h.levels[l].size(); ++j) {
        const st::HNode& hn = h.levels[l][j];
        uint32_t words = hn.has_value && hn.child_mask ? 2 : 1;
        for (uint32_t c = 0; c < uint32_t(__builtin_popcount(hn.child_mask)); ++c) words += sub[l + 1][first[l][j] + c];
        sub[l][j] = words;
      }
    }
    quad_words[w].levels.resize(h.levels.size());
    for (size_t l = 0; l < h.levels.size(); ++l)
      for (size_t j = 0; j < h.levels[l].size(); ++j) quad_words[w].levels[l].push_back({h.levels[l][j].morton, sub[l][j]});
  }
  const st::OctreeSharing share_round = st::measure_octree_sharing(oh, true);
  const uint64_t hybrid_words = st::hybrid_octree_quad_words(oh, quad_words);
  uint64_t quad_total_words = 0;
  for (const auto& q : quad_words) quad_total_words += q.levels[0][0].second;
  quad_words.clear();

  const st::MhOctree tree = st::MhOctree::open(oct);
  const st::StackLookup look(tree, set);
  std::vector<std::unique_ptr<st::Evaluator>> ev;
  for (const auto& b : mh) ev.push_back(st::open_mh(b));

  // Receivers on surfaces seen by sample 0, each with a random slice and time.
  st::Rng rng(7);
  std::vector<st::Vec3d> pts;
  std::vector<uint32_t> ws;
  std::vector<double> times;
  while (pts.size() < lookups) {
    const uint64_t x = rng.next() % side, y = rng.next() % side;
    const st::Interval iv = stack.at(x, y, 0);
    if (iv.lo >= st::kLitDepth) continue;
    pts.push_back(receiver_point(set.samples[0], level, x, y, iv.lo));
    ws.push_back(uint32_t(rng.next() % n));
    times.push_back(rng.uniform());
  }
  const size_t m = pts.size();
  auto lit2d = [&](const st::Vec3d& p, uint32_t w) {
    const st::LightPoint lp = set.samples[w].to_light(p);
    const auto t = st::LightSpace::texel_of(level, lp.u, lp.v);
    return ev[w]->lit(t[0], t[1], float(lp.d));
  };
  // Sanity: the shared walk equals N walks, and every lit test equals the uncompressed
  // map's where the receiver is outside the texel's object interval (lossless contract).
  size_t soft_pen = 0;
  for (size_t i = 0; i < std::min<size_t>(m, 500); ++i) {
    for (uint32_t w = 0; w < n; ++w) {
      const st::LightPoint lp = set.samples[w].to_light(pts[i]);
      const auto t = st::LightSpace::texel_of(level, lp.u, lp.v);
      const st::Interval iv = stack.at(t[0], t[1], w);
      const float r = float(lp.d);
      if (r > iv.lo && r <= iv.hi) continue;
      if (look.lit(pts[i], w) != (r <= iv.lo) || lit2d(pts[i], w) != (r <= iv.lo))
        throw st::Error("bench: a lit test differs from the uncompressed map's");
    }
    const float s = look.soft_visibility(pts[i]);
    if (s != look.soft_visibility_independent(pts[i])) throw st::Error("bench: shared and separate walks differ");
    soft_pen += s > 0 && s < 1;
  }

  float acc = 0;
  const size_t ms = std::max<size_t>(1, m / 8);  // soft lookups cost N times more: fewer points
  t0 = Clock::now();
  const st::StackBounds sbounds(tree);
  const double bounds_s = since(t0);
  // The compute floor: the soft lookups again over 32 points cycled (their nodes, a few
  // hundred KB, stay in L2), so that what the full set costs more is the wait for memory.
  const size_t hot_n = std::min<size_t>(32, ms);
  std::vector<st::Vec3d> hot(ms);
  for (size_t i = 0; i < ms; ++i) hot[i] = pts[i % hot_n];
  std::vector<float> batch_out(ms);
  double ns_2d = 0, ns_oct = 0, ns_time = 0, ns_soft = 0, ns_batch = 0, ns_soft_hot = 0, ns_batch_hot = 0, ns_bounded = 0,
         ns_indep = 0, ns_soft2d = 0;
  uint64_t visited = 0, visited_batch = 0, lines_batch = 0, visited_hot = 0, visited_b = 0;
  SideBySide timing;
  timing.add(ns_2d, m, [&] { for (size_t i = 0; i < m; ++i) acc += lit2d(pts[i], ws[i]); });
  timing.add(ns_oct, m, [&] { for (size_t i = 0; i < m; ++i) acc += look.lit(pts[i], ws[i]); });
  timing.add(ns_time, m, [&] { for (size_t i = 0; i < m; ++i) acc += look.visibility(pts[i], times[i]); });
  timing.add(ns_soft, ms, [&] {
    visited = 0;
    for (size_t i = 0; i < ms; ++i) acc += look.soft_visibility(pts[i]), visited += st::StackLookup::last_nodes_visited();
  });
  // The batched soft lookup over the same points (walks of kWalkLanes points interleaved).
  timing.add(ns_batch, ms, [&] {
    look.soft_visibility(std::span<const st::Vec3d>(pts.data(), ms), batch_out);
    visited_batch = st::StackLookup::last_nodes_visited();
    lines_batch = st::StackLookup::last_lines_prefetched();
    for (float v : batch_out) acc += v;
  });
  timing.add(ns_soft_hot, ms, [&] {
    visited_hot = 0;
    for (size_t i = 0; i < ms; ++i) acc += look.soft_visibility(hot[i]), visited_hot += st::StackLookup::last_nodes_visited();
  });
  timing.add(ns_batch_hot, ms, [&] {
    look.soft_visibility(hot, batch_out);
    for (float v : batch_out) acc += v;
  });
  timing.add(ns_bounded, ms, [&] {
    visited_b = 0;
    for (size_t i = 0; i < ms; ++i)
      acc += look.soft_visibility_bounded(pts[i], sbounds), visited_b += st::StackLookup::last_nodes_visited();
  });
  timing.add(ns_indep, ms, [&] { for (size_t i = 0; i < ms; ++i) acc += look.soft_visibility_independent(pts[i]); });
  timing.add(ns_soft2d, ms, [&] {
    for (size_t i = 0; i < ms; ++i) {
      uint32_t lit = 0;
      for (uint32_t w = 0; w < n; ++w) lit += lit2d(pts[i], w);
      acc += float(lit) / float(n);
    }
  });
  timing.run(reps);
  look.soft_visibility(std::span<const st::Vec3d>(pts.data(), ms), batch_out);
  for (size_t i = 0; i < ms; ++i)
    if (batch_out[i] != look.soft_visibility(pts[i])) throw st::Error("bench: the batched soft lookup differs");
  for (size_t i = 0; i < std::min<size_t>(ms, 500); ++i)
    if (look.soft_visibility_bounded(pts[i], sbounds) != look.soft_visibility(pts[i]))
      throw st::Error("bench: the bounded soft lookup differs");
  g_sink = acc;
  // Where a soft walk's samples go (MHOCT.md "The batched transforms and the compact
  // path"): the share of consecutive samples on the texel of the one before (their shared
  // walk differs in w alone), and how many levels above a sample's walk end a per-node
  // bounds test (StackBounds) decides it: what storing bounds in the format could save.
  uint64_t same_texel = 0, sample_pairs = 0, levels_early = 0, walked = 0;
  {
    const st::moct::Geometry& tg = tree.geometry();
    for (size_t i = 0; i < std::min<size_t>(ms, 500); ++i) {
      std::array<uint64_t, 2> prev{};
      for (uint32_t w = 0; w < n; ++w) {
        const st::LightPoint lp = set.samples[w].to_light(pts[i]);
        const auto t = st::LightSpace::texel_of(level, lp.u, lp.v);
        if (w > 0) ++sample_pairs, same_texel += t == prev;
        prev = t;
        const float d = float(lp.d);
        st::MhOctree::Cursor c = tree.root(), next;
        uint32_t decide = ~0u;
        for (;;) {
          st::StackBounds::Range r = sbounds.at(c.pos);
          if (c.code == st::moct::kCodeEmpty) {  // as soft_visibility_bounded
            const float v = tree.value(c);
            r.lo = std::min(r.lo, v), r.hi = std::max(r.hi, v);
          }
          if (decide == ~0u && (d <= r.lo || d > r.hi)) decide = c.level;
          if (c.level >= tg.depth()) break;
          uint32_t slot = 0;
          if (tg.splits_xy(c.level)) {
            const uint32_t b = tg.n - tg.xy_bits(c.level + 1);
            slot = uint32_t((t[0] >> b) & 1) | uint32_t((t[1] >> b) & 1) << 1;
          }
          if (tg.splits_w(c.level)) slot |= uint32_t((w >> (tg.k - tg.w_bits(c.level + 1))) & 1) << 2;
          if (!tree.child(c, slot, next)) break;
          c = next;
        }
        levels_early += c.level - std::min(decide, c.level);
        ++walked;
      }
    }
  }
  const double same_texel_share = double(same_texel) / double(std::max<uint64_t>(sample_pairs, 1));
  const double bounds_levels_early = double(levels_early) / double(std::max<uint64_t>(walked, 1));

  const double raw = double(stack.data.size()) * 4;  // float32 depth per texel per slice
  std::printf("slices %u, octree levels %u (xy %u, w %u), samples 0-499 in penumbra: %zu\n", n, oh.geo.levels(), oh.geo.n,
              oh.geo.k, soft_pen);
  std::printf("%-26s %14s %14s %10s\n", "", "octree", "N x 2D MH", "oct/2D");
  std::printf("%-26s %14zu %14zu %10.3f\n", "bytes", oct.size(), mh_bytes, double(oct.size()) / double(mh_bytes));
  std::printf("%-26s %14zu %14zu %10.3f\n", "nodes", oh.node_count(), mh_nodes, double(oh.node_count()) / double(mh_nodes));
  std::printf("%-26s %14.3f %14.3f %10.3f\n", "build s (hierarchy)", oct_build_s, mh_build_s, oct_build_s / mh_build_s);
  std::printf("%-26s %14.3f %14.3f %10.3f\n", "encode s", oct_encode_s, mh_encode_s, oct_encode_s / mh_encode_s);
  std::printf("raw float32 stack %.1f MiB (octree %.3f%% of it); tracing %.2f s for %u slices\n", raw / 1048576.0,
              100.0 * double(oct.size()) / raw, trace_s, n);
  std::printf("sharing (%.1f s): %llu nodes, %llu distinct subtrees (%.3f); %llu children blocks, %llu distinct;\n"
              "  words %llu, every distinct subtree once %llu (%.3f), every distinct block once %llu (%.3f);\n"
              "  %llu distinct subtrees with children occur 2+ times, the largest %llu words\n",
              share_s, (unsigned long long)share.nodes, (unsigned long long)share.unique_subtrees,
              double(share.unique_subtrees) / double(share.nodes), (unsigned long long)share.blocks,
              (unsigned long long)share.unique_blocks, (unsigned long long)share.words,
              (unsigned long long)share.dag_words, double(share.dag_words) / double(share.words),
              (unsigned long long)share.block_dag_words, double(share.block_dag_words) / double(share.words),
              (unsigned long long)share.repeated_inner, (unsigned long long)share.largest_repeated_words);
  std::printf("encoded: %llu words (%.3f of the tree's), %u nodes stored, %llu shared blocks (%llu more out of reach), "
              "%llu blocks through far words (%llu far words), %llu padding words; shifts",
              (unsigned long long)oct_stats.words, double(oct_stats.words) / double(share.words), oct_stats.nodes,
              (unsigned long long)oct_stats.shared_blocks, (unsigned long long)oct_stats.out_of_reach,
              (unsigned long long)oct_stats.far_blocks, (unsigned long long)oct_stats.far_words,
              (unsigned long long)oct_stats.padding_words);
  for (uint32_t l = 0; l < oh.geo.levels(); ++l) std::printf(" %u", unsigned(oct_stats.shift[l]));
  std::printf("\n");
  std::printf("merge (%s): %llu candidates, %llu tests (%llu quick rejects, %llu full rejects), %llu merges, %llu "
              "values moved\n",
              g_oct_merge ? "on" : "off", (unsigned long long)oct_stats.merge_candidates,
              (unsigned long long)oct_stats.merge_tests, (unsigned long long)oct_stats.merge_quick_rejects,
              (unsigned long long)oct_stats.merge_full_rejects, (unsigned long long)oct_stats.merges,
              (unsigned long long)oct_stats.merged_values);
  std::printf("value choice (roundest float in each node's interval): distinct blocks %llu, every distinct block once "
              "%llu words (%.3f)\n",
              (unsigned long long)share_round.unique_blocks, (unsigned long long)share_round.block_dag_words,
              double(share_round.block_dag_words) / double(share_round.words));
  std::printf("hybrid model (per region: octree or the quadtrees): %llu words (%.3f of the octree's, %.3f of the N "
              "quadtrees' %llu)\n",
              (unsigned long long)hybrid_words, double(hybrid_words) / double(share.words),
              double(hybrid_words) / double(quad_total_words), (unsigned long long)quad_total_words);
  if (g_all_2d)
    std::printf("best 2D: N x MH %zu, N x MMH %zu, N x DAG-MH %zu bytes; octree / best %.3f\n", mh_bytes, mmh_bytes,
                dagmh_bytes, double(oct.size()) / double(std::min({mh_bytes, mmh_bytes, dagmh_bytes})));
  std::printf("%-34s %10s %12s\n", "lookup (median ns)", "ns", "x 2D lookup");
  auto row = [&](const char* what, double ns) { std::printf("%-34s %10.1f %12.2f\n", what, ns, ns / ns_2d); };
  row("2D lit (one slice)", ns_2d);
  row("octree lit (one slice)", ns_oct);
  row("visibility(p, time)", ns_time);
  row("soft, shared walk (all N)", ns_soft);
  row("soft, batched interleaved (all N)", ns_batch);
  row("soft, bounded early stop (all N)", ns_bounded);
  row("soft, N octree walks", ns_indep);
  row("soft, N 2D lookups", ns_soft2d);
  std::printf("soft per sample: shared %.1f ns, batched %.1f ns, N octree walks %.1f ns, 2D %.1f ns; shared walk nodes per "
              "point %.1f (batched %.1f)\n",
              ns_soft / n, ns_batch / n, ns_indep / n, ns_soft2d / n, double(visited) / double(ms),
              double(visited_batch) / double(ms));
  std::printf("soft per sample, breakdown: shared %.1f ns (cache-hot floor %.1f), batched %.1f ns (floor %.1f); "
              "%.2f nodes and %.2f new cache lines (prefetches) per sample; the 32 hot points %.1f nodes per point\n",
              ns_soft / n, ns_soft_hot / n, ns_batch / n, ns_batch_hot / n, double(visited) / double(ms) / n,
              double(lines_batch) / double(ms) / n, double(visited_hot) / double(ms));
  std::printf("soft walk: batched %.1f ns per sample, %.2fx a 2D lookup per point (shared walk %.1f ns, %.2fx); "
              "consecutive samples on the same texel %.3f; per-node bounds decide %.2f levels early\n",
              ns_batch / n, ns_batch / ns_2d, ns_soft / n, ns_soft / ns_2d, same_texel_share, bounds_levels_early);
  std::printf("peak RSS %.0f MiB\n", peak_rss_mib());
  std::printf("bounded early stop: %.1f ns per sample, nodes per point %.1f; bounds %.2f s, %zu bytes\n",
              ns_bounded / n, double(visited_b) / double(ms), bounds_s, sbounds.bytes());

  return {{"case", c.name},
          {"scene", c.scene},
          {"light", c.light},
          {"resolution", side},
          {"slices", n},
          {"octree_bytes", oct.size()},
          {"mh2d_bytes", mh_bytes},
          {"bytes_ratio", double(oct.size()) / double(mh_bytes)},
          {"octree_nodes", oh.node_count()},
          {"mh2d_nodes", mh_nodes},
          {"raw_bytes", raw},
          {"trace_s", trace_s},
          {"tracer", embree_only ? "embree" : "auto"},
          {"peak_rss_mib", peak_rss_mib()},
          {"octree_build_s", oct_build_s},
          {"octree_encode_s", oct_encode_s},
          {"mh2d_build_s", mh_build_s},
          {"mh2d_encode_s", mh_encode_s},
          {"lookups", m},
          {"soft_lookups", ms},
          {"ns_2d_lit", ns_2d},
          {"ns_octree_lit", ns_oct},
          {"ns_visibility_time", ns_time},
          {"ns_soft_shared", ns_soft},
          {"ns_soft_octree_walks", ns_indep},
          {"ns_soft_2d", ns_soft2d},
          {"soft_shared_over_2d_lit", ns_soft / ns_2d},
          {"ns_soft_batched", ns_batch},
          {"soft_batched_over_2d_lit", ns_batch / ns_2d},
          {"soft_batched_nodes_per_point", double(visited_batch) / double(ms)},
          {"soft_batched_lines_per_sample", double(lines_batch) / double(ms) / n},
          {"ns_soft_shared_hot", ns_soft_hot},
          {"ns_soft_batched_hot", ns_batch_hot},
          {"soft_hot_nodes_per_point", double(visited_hot) / double(ms)},
          {"time_over_2d_lit", ns_time / ns_2d},
          {"soft_nodes_per_point", double(visited) / double(ms)},
          {"ns_soft_bounded", ns_bounded},
          {"soft_bounded_nodes_per_point", double(visited_b) / double(ms)},
          {"soft_same_texel_share", same_texel_share},
          {"soft_bounds_levels_early", bounds_levels_early},
          {"bounds_s", bounds_s},
          {"bounds_bytes", sbounds.bytes()},
          {"sharing",
           {{"nodes", share.nodes},
            {"distinct_subtrees", share.unique_subtrees},
            {"blocks", share.blocks},
            {"distinct_blocks", share.unique_blocks},
            {"words", share.words},
            {"dag_words", share.dag_words},
            {"block_dag_words", share.block_dag_words},
            {"repeated_inner_subtrees", share.repeated_inner},
            {"largest_repeated_words", share.largest_repeated_words},
            {"block_dag_words_roundest", share_round.block_dag_words},
            {"encoded_words", oct_stats.words},
            {"shared_blocks", oct_stats.shared_blocks},
            {"shared_out_of_reach", oct_stats.out_of_reach},
            {"far_blocks", oct_stats.far_blocks},
            {"far_words", oct_stats.far_words},
            {"padding_words", oct_stats.padding_words},
            {"merge", g_oct_merge},
            {"merges", oct_stats.merges},
            {"merged_values", oct_stats.merged_values},
            {"hybrid_words", hybrid_words},
            {"quad_words", quad_total_words}}},
          {"mmh2d_bytes", mmh_bytes},
          {"dagmh2d_bytes", dagmh_bytes}};
}


// Out-of-core mode (--blocked, the default from 4K^2 per slice): the slices are traced
// (rasterizer for suns, Embree for the area light; --tracer embree forces Embree) into a
// spill file in octree blocks and reduced block by block into the stack pack's cut
// (tiles/encode/stack_blocked.hpp); "octree bytes" are then the pack's raw octree tiles plus
// its grid (the cut at skip level K), and the octree lookups go through StackMap over the
// resident tiles (what a client holding the whole pack does). The N 2D quadtrees are built
// from each slice as it is traced (one slice in memory at a time).
nlohmann::json run_case_blocked(const Case& c, uint32_t level, size_t lookups, int reps, bool embree_only,
                                const std::string& spill_dir) {
  std::printf("\n== %s (blocked): %s, %s, %u^2 per slice\n", c.name.c_str(), c.scene.c_str(), c.light.c_str(), 1u << level);
  std::fflush(stdout);
  const st::Scene scene = st::load_scene(c.scene);
  const st::LightSet set = st::fit_light_set(scene, st::LightSetSpec::parse(c.light));
  std::printf("fitted light set: %s\n", set.spec.to_string().c_str());
  std::printf("map square (slice 0): %.1f m a side, a texel %.3f m; frame %s\n", set.samples[0].extent_uv(),
              set.samples[0].extent_uv() / double(uint64_t(1) << level), st::light_kind_name(set.samples[0].kind()));
  const uint32_t n = set.size();
  const uint64_t side = uint64_t(1) << level;
  uint32_t k = 0;
  while ((1u << k) < n) ++k;
  const st::moct::Geometry g{level, k};
  const uint32_t K = st::default_stack_skip_level(g);
  const uint32_t B = st::stack_block_level(g, K, st::kStackBlockTexels);
  const std::string spill_path = spill_dir + "/bench_stacks_" + std::to_string(::getpid()) + ".spill";
  st::StackSpill spill(spill_path, level, n, B);

  // Trace (and the 2D quadtrees of each slice, and receivers from slice 0).
  std::vector<std::vector<uint8_t>> mh(n);
  size_t mh_bytes = 0, mh_nodes = 0;
  double mh_build_s = 0, mh_encode_s = 0, hook_s = 0;
  st::Rng rng(7);
  std::vector<st::Vec3d> pts;
  std::vector<uint32_t> ws;
  std::vector<double> times;
  auto t0 = Clock::now();
  const std::string by = st::trace_stack_to_spill(
      scene, set, spill, nullptr, {},
      [&](uint32_t w, const st::IntervalTile& tile) {
        const auto h0 = Clock::now();
        if (w == 0) {
          size_t tries = 0;
          while (pts.size() < lookups && tries++ < lookups * 1000) {
            const uint64_t x = rng.next() % side, y = rng.next() % side;
            const st::Interval iv = tile.data[y * side + x];
            if (iv.lo >= st::kLitDepth) continue;
            pts.push_back(receiver_point(set.samples[0], level, x, y, iv.lo));
            ws.push_back(uint32_t(rng.next() % n));
            times.push_back(rng.uniform());
          }
        }
        auto b0 = Clock::now();
        const st::Hierarchy h = st::build_hierarchy(tile);
        mh_build_s += since(b0);
        b0 = Clock::now();
        mh[w] = st::encode_mh(h);
        mh_encode_s += since(b0);
        mh_bytes += mh[w].size();
        mh_nodes += h.node_count();
        hook_s += since(h0);
        std::printf("  slice %u/%u traced (%.0f s)\r", w + 1, n, since(t0));
        std::fflush(stdout);
      },
      embree_only);
  const double trace_s = since(t0) - hook_s;
  std::printf("\n");
  const double rss_trace = peak_rss_mib();

  // The blocked octree and its cut.
  t0 = Clock::now();
  st::BlockedCutStats bst;
  st::BlockedStackCut cut(spill, K, 64 * 1024, spill_path + ".tiles", &bst, g_stack_cells, g_split_cells);
  if (cut.split_cells) std::printf("split cells: %llu below K = %u\n", (unsigned long long)cut.split_cells, K);
  if (cut.slice_cells) std::printf("per-slice cells: %llu of %zu tiles\n", (unsigned long long)cut.slice_cells, cut.tile_count());
  const double oct_s = since(t0);
  const double rss_build = peak_rss_mib();
  cut.grid.light_kind = set.samples[0].kind();
  for (const st::LightSpace& l : set.samples) cut.grid.lights.push_back(l.to_array());
  cut.grid.spec = set.spec.to_string();
  const size_t grid_bytes = cut.grid.serialize().size();
  const size_t oct_bytes = cut.tile_bytes_total + grid_bytes;

  // Resident tiles and the pack lookups.
  std::vector<uint64_t> cells;
  std::vector<std::vector<uint8_t>> bufs;
  std::vector<st::StackTile> trees;  // octree or per-slice cells (--stack-cells)
  for (size_t i = 0; i < cut.tile_count(); ++i) {
    auto [cell, b] = cut.tile(i);
    cells.push_back(cell);
    bufs.push_back(std::move(b));
  }
  trees.reserve(bufs.size());
  for (const auto& b : bufs) trees.push_back(st::StackTile::open(b));
  // The tile source as a resident map keeps it (ResidentStack): one dense entry per cell.
  std::vector<st::StackTileRef> by_cell(cut.grid.entries.size());
  for (size_t i = 0; i < cells.size(); ++i) by_cell.at(cells[i]) = trees[i].ref();
  const st::StackMap map(cut.grid, [&](const uint64_t* cells, uint32_t cn, st::StackTileRef* out) {  // as ResidentStack's
    for (uint32_t i = 0; i < cn; ++i) out[i] = cells[i] < by_cell.size() ? by_cell[cells[i]] : st::StackTileRef();
  });
  std::vector<std::unique_ptr<st::Evaluator>> ev;
  for (const auto& b : mh) ev.push_back(st::open_mh(b));

  const size_t m = pts.size();
  auto lit2d = [&](const st::Vec3d& p, uint32_t w) {
    const st::LightPoint lp = set.samples[w].to_light(p);
    const auto t = st::LightSpace::texel_of(level, lp.u, lp.v);
    return ev[w]->lit(t[0], t[1], float(lp.d));
  };
  // Sanity: every lit test equals the uncompressed map's (read back from the spill) where
  // the receiver is outside the texel's object interval.
  for (size_t i = 0; i < std::min<size_t>(m, 200); ++i)
    for (uint32_t w = 0; w < n; ++w) {
      uint64_t x = 0, y = 0;
      float r = 0;
      map.texel(pts[i], w, x, y, r);
      const st::Interval iv = spill.texel(x, y, w);
      if (r > iv.lo && r <= iv.hi) continue;
      if (map.lit(pts[i], w) != (r <= iv.lo) || lit2d(pts[i], w) != (r <= iv.lo))
        throw st::Error("bench: a lit test differs from the uncompressed map's");
    }
  float acc = 0;
  const size_t ms = std::max<size_t>(1, m / 8);
  std::vector<float> batch_out(ms);
  double ns_2d = 0, ns_oct = 0, ns_time = 0, ns_time_def = 0, ns_soft = 0, ns_batch = 0, ns_soft_sep = 0, ns_soft2d = 0,
         ns_soft_hot = 0;
  // visibility(p, time) as the contract defines it (stack_lookup.hpp): lit() of the two
  // nearest slices blended, or of the one slice at a sample's time.
  auto time_by_definition = [&](const st::Vec3d& p, double time) {
    const double s = std::clamp(time, 0.0, 1.0) * double(n - 1), near = std::nearbyint(s);
    if (std::fabs(s - near) <= 1e-9) return map.lit(p, uint32_t(near)) ? 1.0f : 0.0f;
    const uint32_t a = uint32_t(std::floor(s));
    const float f = float(s - double(a));
    const float la = map.lit(p, a) ? 1.0f : 0.0f, lb = map.lit(p, a + 1) ? 1.0f : 0.0f;
    return la + f * (lb - la);
  };
  SideBySide timing;
  timing.add(ns_2d, m, [&] { for (size_t i = 0; i < m; ++i) acc += lit2d(pts[i], ws[i]); });
  timing.add(ns_oct, m, [&] { for (size_t i = 0; i < m; ++i) acc += map.lit(pts[i], ws[i]); });
  timing.add(ns_time, m, [&] { for (size_t i = 0; i < m; ++i) acc += map.visibility(pts[i], times[i]); });
  timing.add(ns_time_def, m, [&] {  // the contract's definition: two lit() lookups blended
    for (size_t i = 0; i < m; ++i) acc += time_by_definition(pts[i], times[i]);
  });
  timing.add(ns_soft, ms, [&] { for (size_t i = 0; i < ms; ++i) acc += map.soft_visibility(pts[i]); });
  timing.add(ns_batch, ms, [&] {
    map.soft_visibility(std::span<const st::Vec3d>(pts.data(), ms), batch_out);
    for (float v : batch_out) acc += v;
  });
  // The compute floor: the soft lookups over 32 points cycled (their tiles' lines stay in
  // the caches), against the cold figure above: what the loads cost.
  std::vector<st::Vec3d> hot;
  for (size_t i = 0; i < ms; ++i) hot.push_back(pts[i % std::min<size_t>(32, ms)]);
  timing.add(ns_soft_hot, ms, [&] { for (size_t i = 0; i < ms; ++i) acc += map.soft_visibility(hot[i]); });
  timing.add(ns_soft_sep, ms, [&] {
    for (size_t i = 0; i < ms; ++i) {
      uint32_t lit = 0;
      for (uint32_t w = 0; w < n; ++w) lit += map.lit(pts[i], w);
      acc += float(lit) / float(n);
    }
  });
  timing.add(ns_soft2d, ms, [&] {
    for (size_t i = 0; i < ms; ++i) {
      uint32_t lit = 0;
      for (uint32_t w = 0; w < n; ++w) lit += lit2d(pts[i], w);
      acc += float(lit) / float(n);
    }
  });
  timing.run(reps);
  // The soft lookups alone, over and over, for a profiler (perf record): the trace and the
  // cut take minutes, the timed lookups milliseconds.
  for (size_t r = 0; r < g_profile_soft; ++r)
    for (size_t i = 0; i < ms; ++i) acc += map.soft_visibility(pts[i]);
  map.soft_visibility(std::span<const st::Vec3d>(pts.data(), ms), batch_out);
  for (size_t i = 0; i < ms; ++i)
    if (batch_out[i] != map.soft_visibility(pts[i])) throw st::Error("bench: the pack's batched soft lookup differs");
  for (size_t i = 0; i < std::min<size_t>(ms, 200); ++i) {
    uint32_t lit = 0;
    for (uint32_t w = 0; w < n; ++w) lit += map.lit(pts[i], w);
    if (map.soft_visibility(pts[i]) != float(lit) / float(n)) throw st::Error("bench: the pack's soft lookup differs");
  }
  for (size_t i = 0; i < m; ++i)
    if (map.visibility(pts[i], times[i]) != time_by_definition(pts[i], times[i]))
      throw st::Error("bench: the pack's time-interpolated lookup differs from its definition");
  g_sink = acc;
  // Where the soft lookups' samples go: the cell forms they fall in, how many a per-slice
  // cell's bounds decide without a walk (SliceTiles::bounds), how many a per-slice cell
  // walks, and how many samples share one per-slice cell in a row (a lockstep call's size).
  size_t mix_outside = 0, mix_constant = 0, mix_absent = 0, mix_octree = 0, mix_slices = 0, mix_bounded = 0,
         mix_runs = 0, mix_const_slice = 0;
  {
    const st::moct::Geometry& gg = cut.grid.geo;
    const uint32_t KK = cut.grid.skip_level, sx = gg.n - gg.xy_bits(KK), sw = gg.k - gg.w_bits(KK);
    for (size_t i = 0; i < ms; ++i) {
      uint64_t prev = ~uint64_t(0);
      for (uint32_t w = 0; w < n; ++w) {
        uint64_t x = 0, y = 0;
        float r = 0;
        map.texel(pts[i], w, x, y, r);
        if ((x >> gg.n) || (y >> gg.n)) { ++mix_outside, prev = ~uint64_t(0); continue; }
        const uint64_t cell = cut.grid.index(KK, x >> sx, y >> sx, uint64_t(w) >> sw);
        const st::StackEntry& e = cut.grid.entries[cell];
        if (e.kind == 0) { ++mix_constant, prev = ~uint64_t(0); continue; }
        auto it = std::lower_bound(cells.begin(), cells.end(), cell);
        if (it == cells.end() || *it != cell) { ++mix_absent, prev = ~uint64_t(0); continue; }
        const st::StackTileRef t = trees[size_t(it - cells.begin())].ref();
        if (t.octree) { ++mix_octree, prev = ~uint64_t(0); continue; }
        ++mix_slices;
        if (cell != prev) ++mix_runs;
        prev = cell;
        const uint32_t lw = w & ((1u << sw) - 1);
        const st::SliceTiles::Bounds b = t.slices->bounds(lw);
        mix_const_slice += t.slices->is_constant(lw);
        mix_bounded += r <= b.lo || r > b.hi;
      }
    }
  }
  const double all_samples = double(ms) * n;
  std::printf("soft samples: outside %.3f, constant cells %.3f, octree cells %.3f, per-slice cells %.3f (constant slices "
              "%.3f, decided by bounds %.3f of all samples; %.1f samples per per-slice run)\n",
              mix_outside / all_samples, mix_constant / all_samples, mix_octree / all_samples, mix_slices / all_samples,
              mix_const_slice / all_samples, mix_bounded / all_samples, mix_runs ? double(mix_slices) / double(mix_runs) : 0.0);
  const double rss_end = peak_rss_mib();
  const double raw = double(side * side) * n * 4;
  std::printf("slices %u, octree levels %u (xy %u, w %u), skip level %u, block level %u (%llu blocks), bounds by %s\n", n,
              g.levels(), g.n, g.k, cut.grid.skip_level, B, (unsigned long long)bst.blocks, by.c_str());
  std::printf("%-26s %14s %14s %10s\n", "", "octree (cut)", "N x 2D MH", "oct/2D");
  std::printf("%-26s %14zu %14zu %10.3f\n", "bytes", oct_bytes, mh_bytes, double(oct_bytes) / double(mh_bytes));
  std::printf("%-26s %14llu %14zu\n", "nodes", (unsigned long long)bst.octree_nodes, mh_nodes);
  std::printf("%-26s %14.3f %14.3f\n", "build+encode s", oct_s, mh_build_s + mh_encode_s);
  std::printf("tiles %zu (%llu bytes, largest %llu), grid %zu bytes; raw float32 stack %.1f MiB; tracing %.2f s\n",
              cut.tile_count(), (unsigned long long)cut.tile_bytes_total, (unsigned long long)cut.max_tile_bytes,
              grid_bytes, raw / 1048576.0, trace_s);
  std::printf("peak RSS: after tracing (and the 2D builds) %.0f MiB, after the blocked build %.0f MiB, at the end %.0f MiB\n",
              rss_trace, rss_build, rss_end);
  std::printf("%-34s %10s %12s\n", "lookup (median ns)", "ns", "x 2D lookup");
  auto row = [&](const char* what, double ns) { std::printf("%-34s %10.1f %12.2f\n", what, ns, ns / ns_2d); };
  row("2D lit (one slice)", ns_2d);
  row("pack lit (one slice)", ns_oct);
  row("pack visibility(p, time)", ns_time);
  row("pack time, two lit() (definition)", ns_time_def);
  row("pack soft (all N, shared walk)", ns_soft);
  row("pack soft, batched interleaved", ns_batch);
  row("pack soft, 32 points (cache-hot)", ns_soft_hot);
  row("pack soft, N lit() lookups", ns_soft_sep);
  row("soft, N 2D lookups", ns_soft2d);
  std::printf("soft per sample: pack %.1f ns, batched %.1f ns (N lit() %.1f ns), 2D %.1f ns\n", ns_soft / n, ns_batch / n,
              ns_soft_sep / n, ns_soft2d / n);
  return {{"case", c.name},
          {"mode", "blocked"},
          {"scene", c.scene},
          {"light", c.light},
          {"resolution", side},
          {"slices", n},
          {"bounds_by", by},
          {"octree_bytes", oct_bytes},
          {"octree_tile_bytes", cut.tile_bytes_total},
          {"grid_bytes", grid_bytes},
          {"skip_level", cut.grid.skip_level},
          {"block_level", B},
          {"blocks", bst.blocks},
          {"mh2d_bytes", mh_bytes},
          {"bytes_ratio", double(oct_bytes) / double(mh_bytes)},
          {"octree_nodes", bst.octree_nodes},
          {"mh2d_nodes", mh_nodes},
          {"raw_bytes", raw},
          {"trace_s", trace_s},
          {"octree_build_encode_s", oct_s},
          {"mh2d_build_s", mh_build_s},
          {"mh2d_encode_s", mh_encode_s},
          {"lookups", m},
          {"soft_lookups", ms},
          {"ns_2d_lit", ns_2d},
          {"ns_pack_lit", ns_oct},
          {"ns_pack_visibility_time", ns_time},
          {"ns_pack_time_two_lit", ns_time_def},
          {"stack_cells", g_stack_cells_name},
          {"slice_cells", cut.slice_cells},
          {"tiles", cut.tile_count()},
          {"ns_pack_soft", ns_soft},
          {"ns_pack_soft_separate", ns_soft_sep},
          {"ns_pack_soft_batched", ns_batch},
          {"ns_pack_soft_hot", ns_soft_hot},
          {"soft_share_octree_cells", mix_octree / all_samples},
          {"soft_share_slice_cells", mix_slices / all_samples},
          {"soft_share_constant_cells", mix_constant / all_samples},
          {"soft_share_decided_by_slice_bounds", mix_bounded / all_samples},
          {"soft_samples_per_slice_run", mix_runs ? double(mix_slices) / double(mix_runs) : 0.0},
          {"ns_soft_2d", ns_soft2d},
          {"peak_rss_mib_trace", rss_trace},
          {"peak_rss_mib_build", rss_build},
          {"peak_rss_mib_end", rss_end}};
}

}  // namespace

int main(int argc, char** argv) {
  try {
    uint32_t level = 8, city_n = 32, hair_n = 64;
    std::string hair_jitter = "0.5", hair_frame = "window";
    size_t lookups = 20000;
    int reps = 3;
    std::string which = "all", json_path = "build/bench_stacks.json", mode = "auto", tracer = "auto", spill_dir = "/tmp",
                frame = "ground";
    st::bench::Options opt("bench_stacks", "Shadow-map stacks (MH 2016, 4) beside N 2D maps: bytes, build time, lookups");
    opt.with("--res", [&](const std::string& v) { level = st::parse_resolution(v); }, "Map side per slice [256]")
        .value("--city-samples", city_n, "Sun samples of the city cases")
        .value("--hair-samples", hair_n, "Area light samples of the hairball and engine-area cases")
        .value("--lookups", lookups, "Lookups per kind")
        .value("--hair-jitter", hair_jitter, "The hairball area light's jitter")
        .value("--hair-frame", hair_frame, "The hairball area light's frame: window, translate or both")
        .value("--reps", reps, "Median of R rounds")
        .value("--case", which, "city, city-hour, hairball, engine, engine-area, real or all")
        .value("--json", json_path, "Write the rows as JSON to PATH")
        .value("--mode", mode, "auto, whole or blocked")
        .value("--tracer", tracer, "auto or embree")
        .value("--spill-dir", spill_dir, "Folder for the traced slices' spill (blocked mode)")
        .value("--frame", frame, "The sun paths' frame: ground, ortho or both")
        .flag("--all-2d", g_all_2d, "Whole mode: every slice also encoded as MMH and DAG-MH")
        .flag("--split-cells", g_split_cells, "Blocked mode: a cell over 64 KiB is split below K")
        .value("--profile-soft", g_profile_soft, "Blocked mode: N more passes of the soft lookups after the timings (for perf)")
        .with("--stack-cells", [&](const std::string& v) { g_stack_cells = st::parse_stack_cells(g_stack_cells_name = v); },
              "Blocked mode: the cells' form: octree, slices or smaller")
        .with("--oct-merge", [&](const std::string& v) {
                if (v != "on" && v != "off") throw st::Error("--oct-merge: expected on or off");
                g_oct_merge = v == "on";
              }, "The whole-stack octree with the encoder's subtree merger: on or off");
    opt.parse(argc, argv);
    reps = std::max(1, reps);
    if (frame != "ground" && frame != "ortho" && frame != "both") throw st::Error("--frame: expected ground, ortho or both");
    std::vector<std::string> frames;
    if (frame != "ground") frames.push_back("ortho");
    if (frame != "ortho") frames.push_back("ground");
    std::vector<Case> cases;
    for (const std::string& f : frames) {
      const std::string tag = f == "ground" ? "" : "-ortho";
      if (which == "all" || which == "city")
        cases.push_back({"city" + tag, "procedural:city",
                         "sun-path:azimuth=100..260,elevation=25..65,samples=" + std::to_string(city_n) + ",frame=" + f});
      // An hour of the same sun: neighbouring slices differ by a fraction of a degree.
      if (which == "all" || which == "city-hour")
        cases.push_back({"city-hour" + tag, "procedural:city",
                         "sun-path:azimuth=170..185,elevation=50..52,samples=" + std::to_string(city_n) + ",frame=" + f});
    }
    // A real open mesh (assimp's 2CylinderEngine.glb): the same day's sun ("engine"), and an
    // area light over it ("engine-area", --hair-samples samples, window frame) sized from the
    // mesh's box: 3 box heights above its centre, a tenth of its width a side.
    const std::string engine = "/usr/share/assimp/models/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb";
    if (which == "engine" || which == "real")
      cases.push_back({"engine", engine,
                       "sun-path:azimuth=100..260,elevation=25..65,samples=" + std::to_string(city_n) + ",frame=ground"});
    if (which == "engine-area" || which == "real") {
      const st::Aabb b = st::load_scene(engine).bounds();
      const st::Vec3d c = (b.lo + b.hi) * 0.5, e = b.hi - b.lo;
      const double side = 0.1 * std::max(e.x, e.z), up = c.y + 3.0 * std::max({e.x, e.y, e.z});
      char spec[256];
      std::snprintf(spec, sizeof spec, "area:pos=%.3f,%.3f,%.3f,target=%.3f,%.3f,%.3f,size=%.3f,%.3f,samples=%u,jitter=%s,frame=window",
                    c.x, up, c.z, c.x, c.y, c.z, side, side, hair_n, hair_jitter.c_str());
      cases.push_back({"engine-area", engine, spec});
    }
    if (hair_frame != "window" && hair_frame != "translate" && hair_frame != "both")
      throw st::Error("--hair-frame: expected window, translate or both");
    for (const char* hf : {"window", "translate"})
      if ((which == "all" || which == "hairball") && (hair_frame == hf || hair_frame == "both"))
        cases.push_back({std::string(hf) == "window" ? "hairball" : "hairball-translate", "procedural:hairball",
                         "area:pos=0,25,0,target=0,0,0,size=4,4,samples=" + std::to_string(hair_n) +
                             ",jitter=" + hair_jitter + ",frame=" + hf});
    if (cases.empty()) throw st::Error("--case: expected city, city-hour, hairball, engine, engine-area, real or all");
    nlohmann::json out = nlohmann::json::array();
    if (mode != "auto" && mode != "whole" && mode != "blocked") throw st::Error("--mode: expected auto, whole or blocked");
    if (tracer != "auto" && tracer != "embree") throw st::Error("--tracer: expected auto or embree");
    const bool blocked = mode == "blocked" || (mode == "auto" && level >= 12);
    for (const Case& c : cases)
      out.push_back(blocked ? run_case_blocked(c, level, lookups, reps, tracer == "embree", spill_dir)
                            : run_case(c, level, lookups, reps, tracer == "embree"));
    std::ofstream(json_path) << out.dump(2) << "\n";
    std::printf("\nwrote %s\n", json_path.c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_stacks: %s\n", e.what());
    return 1;
  }
  return 0;
}
