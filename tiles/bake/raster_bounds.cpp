// The light-space rasterizer of canonical depth bounds: see raster_bounds.hpp.
#include "tiles/bake/raster_bounds.hpp"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <optional>
#include <array>
#include <chrono>
#include <cmath>
#include <string>
#include <vector>

#include "common/error.hpp"
#include "tiles/bake/canonical_coverage.hpp"

namespace st {
namespace {

using Clock = std::chrono::steady_clock;

constexpr uint32_t kTile = RasterBounds::kTile;
constexpr uint32_t kTileTexels = kTile * kTile;
// A triangle whose grown box spans more grid cells than this is kept in a list that every
// region checks instead (ground slabs, sky-wide quads): the grid stays O(triangles).
constexpr uint64_t kMaxGridCellsPerTriangle = 64;
// Margin of a triangle's grid box in light space (u, v): four level-20 texels, more than
// the one texel (plus half a texel for the centre) of the texel boxes it must contain.
constexpr double kGridMargin = 0x1p-18;

// The fast form of a directed edge's value under the sun (canonical_coverage.hpp).
using EdgeSetup = CanonicalEdgeFast;

struct TriSetup {
  EdgeSetup e[3];               // a -> b, b -> c, c -> a in the scene's winding
  // The sign every covered texel's edges share: the three exact edge values add up to
  // d . ((b - a) x (c - a)), independent of o, so a covered texel (all three definition
  // signs equal) has this sign whenever that sum exceeds the edges' bounds; 0 where the
  // sum is too small to tell (then no span culling).
  double sigma;
  double nx, ny, nz, pd, den;   // canonical plane (canonical_depth.hpp): n, n . a, n . dir
  std::array<double, 4> box;    // light-space u0, v0, u1, v1 of the scene vertices
  uint32_t tri;                 // scene triangle index
  uint32_t mesh;
  bool closed;
};

using canonical_detail::abs3;
using canonical_detail::cross_abs;

EdgeSetup edge_setup(const Vec3d& a, const Vec3d& b, const Vec3d& d, const Vec3d& o_max) {
  return CanonicalEdgeFast::of(a, b, d, o_max);
}

// Classification of a run of texels against a triangle's edges: kOutside, the facing
// (+1 or -1) where every fast edge value is beyond its bound, or kUnsure where the
// definition itself must decide (canonical_cover).
constexpr int8_t kOutside = 0, kUnsure = 2;

// sigma != 0: a texel is covered only with all three signs equal to sigma, so it is
// outside as soon as one sigma * value is below -bound; a straight-line loop over the
// run (no data-dependent branches) that the compiler vectorizes.
void classify_oriented(const TriSetup& T, const double* ox, const double* oy, const double* oz, int n,
                       int8_t* cls) {
  double c[3], nx[3], ny[3], nz[3], b[3];
  for (int k = 0; k < 3; ++k)  // sigma * (c + o . n) = sigma c + o . (sigma n), exactly
    c[k] = T.sigma * T.e[k].c, nx[k] = T.sigma * T.e[k].nx, ny[k] = T.sigma * T.e[k].ny,
    nz[k] = T.sigma * T.e[k].nz, b[k] = T.e[k].bound;
  const int8_t facing = int8_t(T.sigma);
  for (int i = 0; i < n; ++i) {
    const double a0 = c[0] + (ox[i] * nx[0] + oy[i] * ny[0] + oz[i] * nz[0]);
    const double a1 = c[1] + (ox[i] * nx[1] + oy[i] * ny[1] + oz[i] * nz[1]);
    const double a2 = c[2] + (ox[i] * nx[2] + oy[i] * ny[2] + oz[i] * nz[2]);
    const bool in = (a0 > b[0]) & (a1 > b[1]) & (a2 > b[2]);
    const bool out = (a0 < -b[0]) | (a1 < -b[1]) | (a2 < -b[2]);
    cls[i] = out ? kOutside : (in ? facing : kUnsure);
  }
}

// sigma == 0 (edge-on or tiny triangles): either orientation may be covered.
void classify_any(const TriSetup& T, const double* ox, const double* oy, const double* oz, int n,
                  int8_t* cls) {
  for (int i = 0; i < n; ++i) {
    int sg[3];
    for (int k = 0; k < 3; ++k) {
      const EdgeSetup& E = T.e[k];
      const double val = E.c + (ox[i] * E.nx + oy[i] * E.ny + oz[i] * E.nz);
      sg[k] = val > E.bound ? 1 : (val < -E.bound ? -1 : 0);
    }
    const bool pos = sg[0] > 0 || sg[1] > 0 || sg[2] > 0, neg = sg[0] < 0 || sg[1] < 0 || sg[2] < 0;
    const bool sure = sg[0] != 0 && sg[1] != 0 && sg[2] != 0;
    cls[i] = pos && neg ? kOutside : (sure ? int8_t(sg[0]) : kUnsure);
  }
}

struct Candidate {
  uint32_t setup;              // index into setups
  int32_t x0, y0, x1, y1;      // texel box inside the region, inclusive
};

// Per-thread scratch for one tile: texel origins and fragment lists (their capacity is
// kept from tile to tile, so nothing is allocated per texel once warm).
// A candidate of the skip test (RasterSkip): its t range over the tile's texel centres
// (conservative) and whether it covers every texel centre of the tile, or none.
struct SkipInfo {
  uint32_t setup;
  double tmin, tmax;  // over the tile, padded
  double t[4], pad;   // at the four corner texels, and how far any texel's t is from affine
};
// Whether b's t exceeds a's by more than `gap` at every texel of the tile: b - a is affine
// in the texel origin too, so its corner values (less both pads) bound it from below.
bool after(const SkipInfo& a, const SkipInfo& b, double gap) {
  for (int q = 0; q < 4; ++q) {
    const double d = b.t[q] - a.t[q];
    if (!(d - (a.pad + b.pad) - 0x1p-44 * (std::fabs(b.t[q]) + std::fabs(a.t[q])) > gap)) return false;
  }
  return true;
}

// The origins of the four corner texels of a tile or region, (x0, y0), (x1, y0), (x0, y1), (x1, y1).
struct Corners {
  double ox[4], oy[4], oz[4];
};

// A candidate that does not miss the whole tile or region (classify()).
struct Live {
  SkipInfo info;
  int8_t sigma;
  bool closed;
  uint32_t mesh;
};
// The non-missing candidates of one closed mesh facing one way, as one surface (classify()):
// per corner the smallest and largest of their planes' t, and the largest pad.
struct Patch {
  double lo[4], hi[4], pad = 0, tmin = 0, tmax = 0;
};
// Directed edge by its endpoints' positions (make_patch()).
struct DirEdge {
  Vec3d a, b;
  uint32_t member;
  int k;
};

struct Scratch {
  std::vector<SkipInfo> others, fronts, backs;  // skip_tile()
  std::vector<Live> live;                       // classify()
  std::vector<uint32_t> members;                // make_patch(), classify_open()
  std::vector<uint8_t> in_layer;                // classify_open()
  std::vector<DirEdge> edges;                   // make_patch()
  std::vector<uint32_t> setup_ids;              // classify()'s candidates
  std::vector<uint32_t> cover;  // skip_tile(): the setups covering every texel centre of the tile
  bool known = false;           // skip_tile(): every candidate covers the whole tile or misses it
  double ox[kTileTexels], oy[kTileTexels], oz[kTileTexels];
  double nearest[kTileTexels];
  // Static rule, tiles without closed triangles: the nearest hit's depth and the smallest
  // depth above it (add_hit()).
  float first_depth[kTileTexels], next_depth[kTileTexels];
  std::vector<CanonicalHit> frags[kTileTexels];
};

}  // namespace

struct RasterBounds::Impl {
  LightSpace light;
  Vec3d centre, dir;
  Vec3d o_round;  // bound on |computed texel origin - its exact affine value|, per axis
  std::vector<Vec3d> v;                       // recentred vertices
  std::vector<std::array<uint32_t, 3>> tri;   // scene triangles
  std::vector<uint32_t> mesh;                 // mesh of each triangle
  std::vector<uint8_t> closed;                // 1 when its mesh is closed
  std::vector<TriSetup> setups;               // triangles a texel ray can hit
  bool any_closed = false;
  double setup_s = 0;
  // Uniform grid over light space [0, 1)^2 of the setups' grown boxes.
  uint32_t grid_side = 1;
  std::vector<uint32_t> grid_start, grid_items, big;
  std::vector<std::array<uint32_t, 2>> grid_first;  // per setup: first grid cell (gx, gy)
  mutable tbb::enumerable_thread_specific<Scratch> scratch;
  RasterSkip skip = RasterSkip::exact;
  bool static_rule = false;  // TraceMode::static_bounds
  mutable std::atomic<uint64_t> skipped{0};
  // Static rule: the most candidates an open layer may have (classify_open()).
  static constexpr size_t kMaxLayer = 48;

  Impl(const Scene& scene, const LightSpace& l);
  std::array<int64_t, 4> grid_range(double u0, double v0, double u1, double v1) const {
    auto cell = [&](double w) {
      const double f = std::floor(w * grid_side);
      return int64_t(std::clamp(f, 0.0, double(grid_side - 1)));
    };
    return {cell(u0), cell(v0), cell(u1), cell(v1)};
  }
  std::vector<Candidate> candidates(const TraceRegion& r) const;
  void tile(const TraceRegion& r, const Candidate* cand, const uint32_t* ids, size_t n,
            uint32_t bi, uint32_t bj, IntervalTile& out, DepthBoundsStats& st) const;
  bool skip_tile(const Candidate* cand, const uint32_t* ids, size_t n, uint32_t bi, uint32_t bj,
                 uint32_t tw, uint32_t th, Scratch& s, IntervalTile& out, DepthBoundsStats& st) const;
  // The skip test on the four corner texels' origins of a tile or region, over the setups
  // `ids` (every triangle that may cover one of its texel centres): sets s.known and
  // s.cover; with `narrow`, true and `iv` when the narrow test proves one interval.
  bool classify(const Corners& c, const std::vector<uint32_t>& ids, bool narrow, Scratch& s, Interval& iv) const;
  std::optional<Interval> region_interval(uint32_t level, uint64_t x0, uint64_t y0, uint64_t side) const;
  bool make_patch(const Corners& c, Scratch& s, uint32_t mesh, int8_t sigma, Patch& p) const;
  bool cover_once(const Corners& c, Scratch& s, int8_t sigma, Patch& p) const;
  bool classify_open(const Corners& c, Scratch& s, Interval& iv) const;
  // A hit of an open-only tile: the nearest t and, under the static rule, the depths.
  void add_hit(Scratch& s, uint32_t k, double t) const {
    if (!static_rule) {
      s.nearest[k] = std::min(s.nearest[k], t);
      return;
    }
    const float d = canonical_depth(light, t);  // monotone in t: depths order as t does
    if (t < s.nearest[k]) {
      if (d < s.first_depth[k]) s.next_depth[k] = s.first_depth[k];
      s.nearest[k] = t, s.first_depth[k] = d;
    } else if (d > s.first_depth[k]) {
      s.next_depth[k] = std::min(s.next_depth[k], d);
    }
  }
  // The static-geometry interval of a reduced texel (TraceMode::static_bounds, as the
  // tracer ends it): an open result (hi = lo, no fallback) of a non-empty hit list
  // reaches to just below `next`, the smallest depth above lo (INFINITY: none, then 1).
  static Interval widen_static(Interval iv, float next) {
    return Interval{iv.lo, next == INFINITY ? kLitDepth : std::max(iv.lo, std::nextafter(next, -INFINITY))};
  }
  static float next_depth_after(const LightSpace& light, const CanonicalHit* h, size_t n, float lo) {
    for (size_t i = 0; i < n; ++i)
      if (const float d = canonical_depth(light, h[i].t); d > lo) return d;
    return INFINITY;
  }
  bool classify_patches(const Corners& c, Scratch& s, Interval& iv) const;
  Interval texel_reference(uint32_t level, uint64_t x, uint64_t y) const;
};

RasterBounds::Impl::Impl(const Scene& scene, const LightSpace& l) : light(l) {
  const auto t0 = Clock::now();
  if (!light.parallel())
    throw Error("raster builder: only sun lights are supported (use the tracer)");
  const size_t nv = scene.vertices.size(), nt = scene.triangles.size();
  if (nt >= (size_t(1) << 32)) throw Error("raster builder: scene '" + scene.name + "' has too many triangles");
  for (size_t i = 0; i < nt; ++i)
    for (uint32_t k : scene.triangles[i])
      if (k >= nv)
        throw Error("raster builder: scene '" + scene.name + "' triangle " + std::to_string(i) +
                    " references vertex " + std::to_string(k) + " of " + std::to_string(nv));
  for (size_t k = 0; k < nv; ++k)
    if (!is_finite(scene.vertices[k]))
      throw Error("raster builder: scene '" + scene.name + "' vertex " + std::to_string(k) + " is not finite");
  const Aabb b = scene.bounds();
  centre = b.empty() ? Vec3d{0, 0, 0} : b.center();
  v.reserve(nv);
  for (const Vec3d& p : scene.vertices) v.push_back(p - centre);
  tri = scene.triangles;
  mesh.assign(nt, 0);
  closed.assign(nt, 0);
  for (uint32_t m = 0; m < scene.meshes.size(); ++m) {
    const Mesh& me = scene.meshes[m];
    if (uint64_t(me.first_triangle) + me.triangle_count > nt)
      throw Error("raster builder: scene '" + scene.name + "' mesh " + std::to_string(m) +
                  " references triangles past the end");
    for (uint32_t t = me.first_triangle; t < me.first_triangle + me.triangle_count; ++t) {
      mesh[t] = m;
      closed[t] = me.closed ? 1 : 0;
    }
  }
  any_closed = std::find(closed.begin(), closed.end(), 1) != closed.end();  // as the tracer
  dir = light.texel_ray(0, 0, 0).dir;  // the sun's rays share one direction
  // Every texel centre of every level <= kMaxLevel lies in the hull of the level-20
  // corner texels' centres; the origin is affine in the centre up to a few roundings.
  Vec3d o_max{0, 0, 0};
  const uint64_t last = (uint64_t(1) << kMaxLevel) - 1;
  for (uint64_t y : {uint64_t(0), last})
    for (uint64_t x : {uint64_t(0), last}) {
      const Vec3d o = abs3(light.texel_ray(kMaxLevel, x, y).origin - centre);
      o_max = {std::max(o_max.x, o.x), std::max(o_max.y, o.y), std::max(o_max.z, o.z)};
    }
  o_max = o_max * (1 + 0x1p-30) + Vec3d{0x1p-1000, 0x1p-1000, 0x1p-1000};
  {
    // How far a computed texel origin can be from the exact affine function of the texel
    // centre: a few roundings of the magnitudes texel_ray adds (its origin, the steps
    // across the map, ray_axis * near: forward, or the ground frame's sheared axis) and of the recentring; 2^-40 of them is a thousand
    // times more than that.
    Vec3d g = abs3(centre) + o_max * 4 + abs3(light.ray_axis() * light.near_plane());
    for (uint64_t y : {uint64_t(0), last})
      for (uint64_t x : {uint64_t(0), last}) g = g + abs3(light.texel_ray(kMaxLevel, x, y).origin);
    o_round = g * 0x1p-40;
  }

  // Per triangle in parallel (kept[t] says whether it can be hit), then compacted.
  std::vector<TriSetup> all(nt);
  std::vector<uint8_t> kept(nt, 0);
  tbb::parallel_for(uint32_t(0), uint32_t(nt), [&](uint32_t t) {
    const Vec3d& a = v[tri[t][0]];
    const Vec3d& bb = v[tri[t][1]];
    const Vec3d& c = v[tri[t][2]];
    const CanonicalPlane plane = CanonicalPlane::of(a, bb, c);
    const double den = dot(plane.n, dir);
    if (den == 0) return;  // the ray lies in the plane: never a hit (CanonicalPlane::t)
    TriSetup& s = all[t];
    s.e[0] = edge_setup(a, bb, dir, o_max);
    s.e[1] = edge_setup(bb, c, dir, o_max);
    s.e[2] = edge_setup(c, a, dir, o_max);
    {
      const double sum = dot(dir, cross(bb - a, c - a));
      const double sum_bound =
          0x1p-47 * dot(abs3(dir), cross_abs(abs3(bb) + abs3(a), abs3(c) + abs3(a))) + 0x1p-1000;
      const double margin = sum_bound + s.e[0].bound + s.e[1].bound + s.e[2].bound;
      s.sigma = sum > margin ? 1 : (sum < -margin ? -1 : 0);
    }
    s.nx = plane.n.x, s.ny = plane.n.y, s.nz = plane.n.z, s.pd = plane.d, s.den = den;
    s.box = {INFINITY, INFINITY, -INFINITY, -INFINITY};
    for (uint32_t k = 0; k < 3; ++k) {
      const LightPoint lp = light.to_light(scene.vertices[tri[t][k]]);
      s.box[0] = std::min(s.box[0], lp.u), s.box[1] = std::min(s.box[1], lp.v);
      s.box[2] = std::max(s.box[2], lp.u), s.box[3] = std::max(s.box[3], lp.v);
    }
    if (!(s.box[2] >= -kGridMargin && s.box[3] >= -kGridMargin && s.box[0] <= 1 + kGridMargin &&
          s.box[1] <= 1 + kGridMargin))
      return;  // outside the map
    s.tri = t, s.mesh = mesh[t], s.closed = closed[t] != 0;
    kept[t] = 1;
  });
  size_t n_kept = 0;  // compacted in place: no second copy at the peak
  for (size_t t = 0; t < nt; ++t)
    if (kept[t]) all[n_kept++] = all[t];
  all.resize(n_kept);
  setups = std::move(all);

  // The grid: about two setups per cell, at most 1024 cells a side.
  while (grid_side < 1024 && uint64_t(grid_side) * grid_side * 2 < setups.size()) grid_side *= 2;
  const size_t cells = size_t(grid_side) * grid_side;
  grid_start.assign(cells + 1, 0);
  grid_first.resize(setups.size());
  std::vector<uint8_t> is_big(setups.size(), 0);
  std::vector<uint32_t> cursor;
  for (int pass = 0; pass < 2; ++pass) {
    for (uint32_t s = 0; s < setups.size(); ++s) {
      const auto& bx = setups[s].box;
      const auto g = grid_range(bx[0] - kGridMargin, bx[1] - kGridMargin, bx[2] + kGridMargin,
                                bx[3] + kGridMargin);
      if (pass == 0) {
        grid_first[s] = {uint32_t(g[0]), uint32_t(g[1])};
        if (uint64_t(g[2] - g[0] + 1) * uint64_t(g[3] - g[1] + 1) > kMaxGridCellsPerTriangle) {
          is_big[s] = 1;
          big.push_back(s);
        }
      }
      if (is_big[s]) continue;
      for (int64_t gy = g[1]; gy <= g[3]; ++gy)
        for (int64_t gx = g[0]; gx <= g[2]; ++gx) {
          const size_t cell = size_t(gy) * grid_side + size_t(gx);
          if (pass == 0) ++grid_start[cell + 1];
          else grid_items[cursor[cell]++] = s;
        }
    }
    if (pass == 0) {
      for (size_t c = 0; c < cells; ++c) grid_start[c + 1] += grid_start[c];
      grid_items.resize(grid_start[cells]);
      cursor.assign(grid_start.begin(), grid_start.end() - 1);
    }
  }
  setup_s = std::chrono::duration<double>(Clock::now() - t0).count();
}

std::vector<Candidate> RasterBounds::Impl::candidates(const TraceRegion& r) const {
  const double side = std::ldexp(1.0, int(r.level));
  std::vector<Candidate> out;
  auto consider = [&](uint32_t s) {
    const auto& bx = setups[s].box;
    // Texel x is a candidate when its centre (x + 0.5) / side may lie in the box: one
    // texel of margin on each side (raster_bounds.hpp).
    const double x0 = std::floor(bx[0] * side - 0.5) - 1 - double(r.x0);
    const double y0 = std::floor(bx[1] * side - 0.5) - 1 - double(r.y0);
    const double x1 = std::ceil(bx[2] * side - 0.5) + 1 - double(r.x0);
    const double y1 = std::ceil(bx[3] * side - 0.5) + 1 - double(r.y0);
    if (!(x1 >= 0 && y1 >= 0 && x0 < r.width && y0 < r.height)) return;
    out.push_back(Candidate{s, int32_t(std::max(0.0, x0)), int32_t(std::max(0.0, y0)),
                            int32_t(std::min(double(r.width - 1), x1)),
                            int32_t(std::min(double(r.height - 1), y1))});
  };
  for (uint32_t s : big) consider(s);
  const auto g = grid_range(double(r.x0) / side, double(r.y0) / side,
                            double(r.x0 + r.width) / side, double(r.y0 + r.height) / side);
  for (int64_t gy = g[1]; gy <= g[3]; ++gy)
    for (int64_t gx = g[0]; gx <= g[2]; ++gx) {
      const size_t cell = size_t(gy) * grid_side + size_t(gx);
      for (uint32_t k = grid_start[cell]; k < grid_start[cell + 1]; ++k) {
        const uint32_t s = grid_items[k];
        // Once per region: in the first cell both the region's and the box's ranges share.
        if (int64_t(std::max<uint32_t>(grid_first[s][0], uint32_t(g[0]))) != gx ||
            int64_t(std::max<uint32_t>(grid_first[s][1], uint32_t(g[1]))) != gy)
          continue;
        consider(s);
      }
    }
  return out;
}

void RasterBounds::Impl::tile(const TraceRegion& r, const Candidate* cand, const uint32_t* ids,
                              size_t n, uint32_t bi, uint32_t bj, IntervalTile& out,
                              DepthBoundsStats& st) const {
  Scratch& s = scratch.local();
  const uint32_t tw = std::min(kTile, r.width - bi), th = std::min(kTile, r.height - bj);
  // The texel origins, operation for operation as LightSpace::texel_ray computes them
  // (origin + axis_u (u E) + axis_v (v E) + ray_axis near, then - centre), with the
  // column and row terms computed once per tile; the reference test pins the equality.
  {
    const double inv = std::ldexp(1.0, -int(r.level)), E = light.extent_uv();
    const Vec3d org = light.origin(), au = light.axis_u(), av = light.axis_v();
    const Vec3d fn = light.ray_axis() * light.near_plane();
    Vec3d col[kTile];
    for (uint32_t i = 0; i < tw; ++i) col[i] = au * ((double(r.x0 + bi + i) + 0.5) * inv * E);
    for (uint32_t j = 0; j < th; ++j) {
      const Vec3d row = av * ((double(r.y0 + bj + j) + 0.5) * inv * E);
      for (uint32_t i = 0; i < tw; ++i) {
        const Vec3d o = org + col[i] + row + fn - centre;
        const uint32_t k = j * kTile + i;
        s.ox[k] = o.x, s.oy[k] = o.y, s.oz[k] = o.z;
      }
    }
  }
  s.known = false;
  if (skip != RasterSkip::off && skip_tile(cand, ids, n, bi, bj, tw, th, s, out, st)) {
    skipped.fetch_add(uint64_t(tw) * th, std::memory_order_relaxed);
    return;
  }
  bool lists = false;
  for (size_t c = 0; c < n; ++c) lists |= setups[cand[ids[c]].setup].closed;
  for (uint32_t k = 0; k < kTileTexels; ++k) {
    s.nearest[k] = INFINITY;
    s.first_depth[k] = s.next_depth[k] = INFINITY;
    if (lists) s.frags[k].clear();
  }
  // The origin steps of one texel along x and y (spans below).
  const Vec3d o00{s.ox[0], s.oy[0], s.oz[0]};
  const Vec3d du = light.texel_ray(r.level, r.x0 + bi + 1, r.y0 + bj).origin - centre - o00;
  const Vec3d dv = light.texel_ray(r.level, r.x0 + bi, r.y0 + bj + 1).origin - centre - o00;
  const Vec3d adu = abs3(du), adv = abs3(dv);
  uint64_t tests = 0;
  if (s.known) {
    // Every candidate covers every texel centre of the tile (facing sigma) or none: the hit
    // lists without edge tests, each t as below, then the same reduction.
    skipped.fetch_add(uint64_t(tw) * th, std::memory_order_relaxed);
    for (uint32_t j = 0; j < th; ++j)
      for (uint32_t i = 0; i < tw; ++i) {
        const uint32_t k = j * kTile + i;
        const double ox = s.ox[k], oy = s.oy[k], oz = s.oz[k];
        for (const uint32_t si : s.cover) {
          const TriSetup& T = setups[si];
          // CanonicalPlane::t, operation for operation (as below).
          const double t = (T.pd - (T.nx * ox + T.ny * oy + T.nz * oz)) / T.den;
          if (!std::isfinite(t) || t < 0 || t > 1) continue;
          if (lists) s.frags[k].push_back(CanonicalHit{t, T.tri, T.mesh, int8_t(T.sigma), T.closed});
          else add_hit(s, k, t);
        }
      }
  }
  for (size_t c = 0; c < (s.known ? 0 : n); ++c) {
    const Candidate& cd = cand[ids[c]];
    const TriSetup& T = setups[cd.setup];
    const int32_t i0 = std::max<int32_t>(cd.x0, int32_t(bi)) - int32_t(bi);
    const int32_t i1 = std::min<int32_t>(cd.x1, int32_t(bi + tw - 1)) - int32_t(bi);
    const int32_t j0 = std::max<int32_t>(cd.y0, int32_t(bj)) - int32_t(bj);
    const int32_t j1 = std::min<int32_t>(cd.y1, int32_t(bj + th - 1)) - int32_t(bj);
    // Row spans: each edge's value is affine in the texel (up to the rounding of the
    // origins), so along a row the texels where sigma * value may reach -bound form an
    // interval. A texel outside it has sigma * fast value < -bound on some edge: that
    // edge's definition sign is -sigma, and a covered texel's signs all equal sigma.
    // The margin covers the bound twice, the origins' rounding, the products' rounding
    // and one texel step; the division's rounding is covered by one texel each side.
    double e0[3] = {}, su[3] = {}, sv[3] = {}, marg[3] = {};
    // Small boxes are cheaper to test texel by texel than to cull.
    const bool spans = T.sigma != 0 && (i1 - i0 + 1) * (j1 - j0 + 1) > 16;
    if (spans)
      for (int k = 0; k < 3; ++k) {
        const EdgeSetup& E = T.e[k];
        const Vec3d an{std::fabs(E.nx), std::fabs(E.ny), std::fabs(E.nz)};
        e0[k] = E.c + (o00.x * E.nx + o00.y * E.ny + o00.z * E.nz);
        su[k] = du.x * E.nx + du.y * E.ny + du.z * E.nz;
        sv[k] = dv.x * E.nx + dv.y * E.ny + dv.z * E.nz;
        const double step = dot(adu, an) + dot(adv, an);
        marg[k] = 2 * E.bound + 64 * dot(o_round, an) + 2 * step +
                  0x1p-40 * (std::fabs(e0[k]) + 2 * kTile * step);
      }
    for (int32_t j = j0; j <= j1; ++j) {
      double xs = i0, xe = i1;
      if (spans)
        for (int k = 0; k < 3 && xs <= xe; ++k) {
          const double a = T.sigma * (e0[k] + j * sv[k]) + marg[k], b = T.sigma * su[k];
          if (b == 0) {
            if (a < 0) xe = xs - 1;
          } else if (b > 0) {
            xs = std::max(xs, std::ceil(-a / b) - 1);
          } else {
            xe = std::min(xe, std::floor(-a / b) + 1);
          }
        }
      if (!(xs <= xe)) continue;
      const int32_t is = int32_t(xs), ie = int32_t(xe);
      const uint32_t row = uint32_t(j) * kTile + uint32_t(is);
      const int n_row = ie - is + 1;
      tests += uint64_t(n_row);
      int8_t cls[kTile];
      if (T.sigma != 0) classify_oriented(T, s.ox + row, s.oy + row, s.oz + row, n_row, cls);
      else classify_any(T, s.ox + row, s.oy + row, s.oz + row, n_row, cls);
      for (int q = 0; q < n_row; ++q) {
        if (cls[q] == kOutside) continue;
        const uint32_t k = row + uint32_t(q);
        const double ox = s.ox[k], oy = s.oy[k], oz = s.oz[k];
        int facing = cls[q];
        if (facing == kUnsure) {
          const auto& tv = tri[T.tri];
          facing = canonical_cover(CoverageRay::of(Vec3d{ox, oy, oz}, dir), v[tv[0]], v[tv[1]], v[tv[2]]);
          if (facing == 0) continue;
        }
        // CanonicalPlane::t, operation for operation.
        const double t = (T.pd - (T.nx * ox + T.ny * oy + T.nz * oz)) / T.den;
        if (!std::isfinite(t) || t < 0 || t > 1) continue;
        if (lists) s.frags[k].push_back(CanonicalHit{t, T.tri, T.mesh, int8_t(facing), T.closed});
        else add_hit(s, k, t);
      }
    }
  }
  st.traversals += tests;
  for (uint32_t j = 0; j < th; ++j)
    for (uint32_t i = 0; i < tw; ++i) {
      const uint32_t k = j * kTile + i;
      CanonicalResult res;
      float next = INFINITY;  // static rule: the smallest depth above lo
      if (lists) {
        auto& f = s.frags[k];
        if (f.size() == 2) {
          if (f[1] < f[0]) std::swap(f[0], f[1]);
        } else if (f.size() > 2) {
          std::sort(f.begin(), f.end());
        }
        // The commonest closed case, as canonical_interval() ends it: one mesh entered
        // at t0 and left at t1 > t0.
        if (f.size() == 2 && f[0].closed && f[1].closed && f[0].mesh == f[1].mesh && f[0].facing < 0 &&
            f[1].facing > 0 && f[0].t < f[1].t) {
          res.lo_t = f[0].t, res.hi_t = f[1].t;
        } else {
          res = canonical_interval(f.data(), f.size(), 1.0);
        }
        if (static_rule && !f.empty() && !res.fell_back)
          next = next_depth_after(light, f.data(), f.size(), canonical_depth(light, res.lo_t));
      } else if (s.nearest[k] < INFINITY) {
        res.lo_t = res.hi_t = s.nearest[k];
        next = s.next_depth[k];
      }
      Interval iv = canonical_depths(light, res);
      if (static_rule && res.lo_t < INFINITY && !res.fell_back && iv.hi == iv.lo) iv = widen_static(iv, next);
      out.at(bi + i, bj + j) = iv;
      st.hits += res.lo_t < INFINITY;
      st.closed += iv.hi > iv.lo;
      st.fallbacks += res.fell_back;
    }
}

// The skip test (RasterSkip, raster_bounds.hpp). Soundness, per claim:
//  - edge signs: the exact edge value c + o . n is affine in the exact texel origin, itself
//    affine in the texel index, so over the tile's texel centres it lies between its values
//    at the four corner texels. A corner's fast value beyond 2 bound + the origins'
//    rounding (as the row spans' margin) gives every texel centre of the tile the
//    definition's sign: `covers` (all three edges, sigma's side) or `misses` (one edge on
//    the other side at all four corners). Triangles with sigma == 0 are never either.
//  - depths: t = (pd - n . o) / den is affine in o too, so the corner values, padded by
//    the rounding of that expression and of the origins, bound every texel's t.
//  - the hit list: non-candidates never cover a tile texel (binning); a candidate that
//    misses is not in it. When every candidate covers or misses (s.known), a texel's list
//    is the covering ones whose t lies in [0, 1], each facing sigma: tile() builds it
//    without edge tests and reduces it as always (the same bits as the full path).
//  - narrow: the list is F (entering, t in [0, 1]), B (leaving, same closed mesh, t after
//    F's at every texel), open hits after F (ignored while inside, or after the exit),
//    closed hits beyond B by more than the touching window (the run ends before them):
//    canonical_interval() gives lo_t = t_F, hi_t = t_B, and [a, b] lies inside; or with
//    one touching mesh (G entering after F, its B2 leaving after G), hi_t = t_B or t_B2,
//    both >= t_B (see classify()).
// Returns true when it filled the tile (narrow); else sets s.known and s.cover.
bool RasterBounds::Impl::skip_tile(const Candidate* cand, const uint32_t* ids, size_t n, uint32_t bi,
                                   uint32_t bj, uint32_t tw, uint32_t th, Scratch& s, IntervalTile& out,
                                   DepthBoundsStats& st) const {
  const uint32_t corner[4] = {0, tw - 1, (th - 1) * kTile, (th - 1) * kTile + tw - 1};
  Corners c;
  for (int q = 0; q < 4; ++q) c.ox[q] = s.ox[corner[q]], c.oy[q] = s.oy[corner[q]], c.oz[q] = s.oz[corner[q]];
  s.setup_ids.clear();
  for (size_t k = 0; k < n; ++k) s.setup_ids.push_back(cand[ids[k]].setup);
  Interval iv;
  if (!classify(c, s.setup_ids, skip == RasterSkip::narrow || skip == RasterSkip::regions, s, iv)) return false;
  for (uint32_t j = 0; j < th; ++j)
    for (uint32_t i = 0; i < tw; ++i) out.at(bi + i, bj + j) = iv;
  const uint64_t texels = uint64_t(tw) * th;
  st.hits += texels;
  st.closed += iv.lo < iv.hi ? texels : 0;
  return true;
}

bool RasterBounds::Impl::classify(const Corners& c, const std::vector<uint32_t>& ids, bool narrow, Scratch& s,
                                  Interval& iv) const {
  constexpr uint32_t kNone = UINT32_MAX;
  SkipInfo F{kNone, 0, 0, {}, 0}, B{kNone, 0, 0, {}, 0};
  s.others.clear();
  auto& fronts = s.fronts;  // covering front / back faces of closed meshes
  auto& backs = s.backs;
  fronts.clear(), backs.clear(), s.cover.clear(), s.live.clear();
  bool partial = false, unbounded = false;
  for (const uint32_t si : ids) {
    const TriSetup& T = setups[si];
    bool covers = T.sigma != 0, misses = false;
    for (int k = 0; k < 3; ++k) {
      const EdgeSetup& E = T.e[k];
      const Vec3d an{std::fabs(E.nx), std::fabs(E.ny), std::fabs(E.nz)};
      const double m0 = 2 * E.bound + 64 * dot(o_round, an);
      bool all_in = true, all_out = T.sigma != 0;
      for (int q = 0; q < 4; ++q) {
        const double val = T.sigma * (E.c + (c.ox[q] * E.nx + c.oy[q] * E.ny + c.oz[q] * E.nz));
        const double m = m0 + 0x1p-40 * std::fabs(val);
        all_in &= val > m;
        all_out &= val < -m;
      }
      covers &= all_in;
      misses |= all_out;
    }
    if (misses) continue;
    if (covers) s.cover.push_back(si);
    else partial = true;
    // t over the tile: corner values, padded.
    double tmin = INFINITY, tmax = -INFINITY, mag = std::fabs(T.pd);
    const Vec3d an{std::fabs(T.nx), std::fabs(T.ny), std::fabs(T.nz)};
    double extra = 0;
    SkipInfo info{si, 0, 0, {}, 0};
    for (int q = 0; q < 4; ++q) {
      const double t = (T.pd - (T.nx * c.ox[q] + T.ny * c.oy[q] + T.nz * c.oz[q])) / T.den;
      info.t[q] = t;
      tmin = std::min(tmin, t), tmax = std::max(tmax, t);
      extra = std::max(extra, an.x * std::fabs(c.ox[q]) + an.y * std::fabs(c.oy[q]) + an.z * std::fabs(c.oz[q]));
    }
    const double pad = ((mag + extra) * 0x1p-44 + 64 * dot(an, o_round)) / std::fabs(T.den) +
                       0x1p-44 * std::max(std::fabs(tmin), std::fabs(tmax)) + 0x1p-1000;
    if (!std::isfinite(tmin) || !std::isfinite(tmax) || !std::isfinite(pad)) {
      partial = true, unbounded = true;
      break;
    }
    info.tmin = tmin - pad, info.tmax = tmax + pad, info.pad = pad;
    s.live.push_back(Live{info, int8_t(T.sigma), T.closed, T.mesh});
    if (covers && T.closed) (T.sigma < 0 ? fronts : backs).push_back(info);
    else s.others.push_back(info);
  }
  s.known = !partial;
  if (!narrow || unbounded) return false;
  if (static_rule && classify_open(c, s, iv)) return true;
  if (!any_closed) return false;
  if (classify_patches(c, s, iv)) return true;
  // F: the nearest covering front face; B: the nearest covering back face of its mesh after it.
  for (const SkipInfo& f : fronts)
    if (F.setup == kNone || f.tmin < F.tmin) F = f;
  if (F.setup == kNone || !(F.tmin >= 0)) return false;
  const uint32_t mesh_f = setups[F.setup].mesh;
  for (const SkipInfo& b : backs)
    if (setups[b.setup].mesh == mesh_f && after(F, b, 0) && (B.setup == kNone || b.tmin < B.tmin)) B = b;
  if (B.setup == kNone || !(B.tmax <= 1)) return false;
  const double touch = ExitDepthRay::kTouchDouble * 1.0;  // canonical_interval(..., 1.0)
  const double gap = touch * (1 + 0x1p-40);
  // A second closed mesh whose covering front face G is not provably beyond B's touching
  // window (a building standing on the ground slab: its floor and the slab's top
  // coincide): allowed when G lies after F and its own covering back face B2 after G
  // (nearest such). Whatever the order of B and G at a texel (B first, G first, or one
  // group of equal t), the counters never go negative and reach 0 at B or at B2, so hi is
  // t_B or t_B2 > t_B: b below still bounds it. Everything else closed must then lie
  // beyond both exits' touching windows.
  SkipInfo G{kNone, 0, 0, {}, 0}, B2{kNone, 0, 0, {}, 0};
  for (const SkipInfo& f : fronts)
    if (f.setup != F.setup && setups[f.setup].mesh != mesh_f && !after(B, f, gap) && after(F, f, 0) &&
        (G.setup == kNone || f.tmin < G.tmin))
      G = f;
  if (G.setup != kNone) {
    const uint32_t mesh_g = setups[G.setup].mesh;
    for (const SkipInfo& b : backs)
      if (setups[b.setup].mesh == mesh_g && after(G, b, 0) && (B2.setup == kNone || b.tmin < B2.tmin)) B2 = b;
    if (B2.setup == kNone || !(B2.tmax <= 1)) return false;
  }
  for (const SkipInfo& f : fronts)
    if (f.setup != F.setup && f.setup != G.setup) s.others.push_back(f);
  for (const SkipInfo& b : backs)
    if (b.setup != B.setup && b.setup != B2.setup) s.others.push_back(b);
  for (const SkipInfo& o : s.others) {
    if (setups[o.setup].closed ? !after(B, o, gap) || (B2.setup != kNone && !after(B2, o, gap)) : !after(F, o, 0))
      return false;
  }
  const float a = canonical_depth(light, F.tmax), b = canonical_depth(light, B.tmin);
  if (!(a <= b)) return false;
  iv = Interval{a, b};
  return true;
}

// Whether b's t exceeds a's by more than `gap` at every texel: a's largest and b's smallest
// plane values are convex and concave in the texel, so their difference is smallest at a
// corner (the pads bound each plane's rounding).
bool after(const Patch& a, const Patch& b, double gap) {
  for (int q = 0; q < 4; ++q) {
    const double d = b.lo[q] - a.hi[q];
    if (!(d - (a.pad + b.pad) - 0x1p-44 * (std::fabs(b.lo[q]) + std::fabs(a.hi[q])) > gap)) return false;
  }
  return true;
}
Patch patch_of(const SkipInfo& i) {
  Patch p;
  for (int q = 0; q < 4; ++q) p.lo[q] = p.hi[q] = i.t[q];
  p.pad = i.pad, p.tmin = i.tmin, p.tmax = i.tmax;
  return p;
}

// The live candidates of closed mesh `mesh` facing `sigma` as one surface: true when every
// texel centre of the tile or region is covered by exactly one of them. Proof: (1) every
// directed edge of a member is unique and either meets its reverse in exactly one other
// member (an interior edge: one member on each side) or has the whole region strictly on
// one side of its line (corner values beyond the bounds), so no boundary of the members'
// union crosses the region and the number of members covering a point is the same all
// over it (the members all face one way); (2) at some corner that number is decided and
// is 1. Points on interior edges and vertices are covered once by the definition's
// tie-breaking (canonical_coverage.hpp: watertight, never twice).
bool RasterBounds::Impl::make_patch(const Corners& c, Scratch& s, uint32_t mesh, int8_t sigma, Patch& p) const {
  s.members.clear();
  for (uint32_t i = 0; i < s.live.size(); ++i) {
    const Live& l = s.live[i];
    if (!l.closed || l.mesh != mesh) continue;
    if (l.sigma == 0) return false;  // an edge-on member of the mesh: neither side
    if (l.sigma == sigma) s.members.push_back(i);
  }
  return cover_once(c, s, sigma, p);
}

// The live candidates s.members, all facing `sigma`, as one surface: true (and their
// corner depths in p) when every texel centre of the tile or region is covered by exactly
// one of them (the proof above make_patch()).
bool RasterBounds::Impl::cover_once(const Corners& c, Scratch& s, int8_t sigma, Patch& p) const {
  if (s.members.empty()) return false;
  s.edges.clear();
  for (uint32_t m : s.members) {
    const auto& tv = tri[setups[s.live[m].info.setup].tri];
    for (int k = 0; k < 3; ++k) s.edges.push_back(DirEdge{v[tv[k]], v[tv[(k + 1) % 3]], m, k});
  }
  auto less = [](const Vec3d& a, const Vec3d& b) {
    if (a.x != b.x) return a.x < b.x;
    if (a.y != b.y) return a.y < b.y;
    return a.z < b.z;
  };
  auto edge_less = [&](const DirEdge& e, const DirEdge& f) {
    if (less(e.a, f.a)) return true;
    if (less(f.a, e.a)) return false;
    return less(e.b, f.b);
  };
  std::sort(s.edges.begin(), s.edges.end(), edge_less);
  auto same = [](const Vec3d& a, const Vec3d& b) { return a.x == b.x && a.y == b.y && a.z == b.z; };
  for (size_t i = 0; i < s.edges.size(); ++i) {
    const DirEdge& e = s.edges[i];
    if (i + 1 < s.edges.size() && same(s.edges[i + 1].a, e.a) && same(s.edges[i + 1].b, e.b)) return false;
    if (i > 0 && same(s.edges[i - 1].a, e.a) && same(s.edges[i - 1].b, e.b)) return false;
    const DirEdge rev{e.b, e.a, 0, 0};
    auto it = std::lower_bound(s.edges.begin(), s.edges.end(), rev, edge_less);
    if (it != s.edges.end() && same(it->a, e.b) && same(it->b, e.a)) continue;  // interior (unique: above)
    // A boundary edge: the region strictly on one side of its line.
    const EdgeSetup& E = setups[s.live[e.member].info.setup].e[e.k];
    const Vec3d an{std::fabs(E.nx), std::fabs(E.ny), std::fabs(E.nz)};
    const double m0 = 2 * E.bound + 64 * dot(o_round, an);
    bool pos = true, neg = true;
    for (int q = 0; q < 4; ++q) {
      const double val = E.c + (c.ox[q] * E.nx + c.oy[q] * E.ny + c.oz[q] * E.nz);
      const double m = m0 + 0x1p-40 * std::fabs(val);
      pos &= val > m;
      neg &= val < -m;
    }
    if (!pos && !neg) return false;
  }
  bool once = false;
  for (int q = 0; q < 4 && !once; ++q) {
    int count = 0;
    bool unsure = false;
    for (uint32_t mi : s.members) {
      const TriSetup& T = setups[s.live[mi].info.setup];
      int in = 0;
      bool out = false;
      for (int k = 0; k < 3; ++k) {
        const EdgeSetup& E = T.e[k];
        const Vec3d an{std::fabs(E.nx), std::fabs(E.ny), std::fabs(E.nz)};
        const double val = sigma * (E.c + (c.ox[q] * E.nx + c.oy[q] * E.ny + c.oz[q] * E.nz));
        const double m = 2 * E.bound + 64 * dot(o_round, an) + 0x1p-40 * std::fabs(val);
        if (val < -m) out = true;
        else if (val > m) ++in;
      }
      if (out) continue;
      if (in == 3) ++count;
      else unsure = true;
    }
    once = !unsure && count == 1;
  }
  if (!once) return false;
  for (int q = 0; q < 4; ++q) p.lo[q] = INFINITY, p.hi[q] = -INFINITY;
  p.pad = 0, p.tmin = INFINITY, p.tmax = -INFINITY;
  for (uint32_t mi : s.members) {
    const SkipInfo& i = s.live[mi].info;
    for (int q = 0; q < 4; ++q) p.lo[q] = std::min(p.lo[q], i.t[q]), p.hi[q] = std::max(p.hi[q], i.t[q]);
    p.pad = std::max(p.pad, i.pad), p.tmin = std::min(p.tmin, i.tmin), p.tmax = std::max(p.tmax, i.tmax);
  }
  return true;
}

// The narrow test over surfaces (patches) instead of single triangles: one closed mesh's
// front patch F and back patch B, each covering every texel centre exactly once, with F
// before B everywhere; optionally a second closed mesh touching B (G, B2 as in classify());
// every other live candidate beyond: closed ones beyond the exits' touching windows, open
// ones after F. Each texel's hit list then holds one F, one B (and one G, one B2) in the
// orders classify() reasons about, so [largest F t, smallest B t] lies inside its interval.
bool RasterBounds::Impl::classify_patches(const Corners& c, Scratch& s, Interval& iv) const {
  constexpr uint32_t kNone = UINT32_MAX;
  uint32_t mesh_f = kNone;
  double first = INFINITY;
  for (const Live& l : s.live)
    if (l.closed && l.sigma < 0 && l.info.tmin < first) first = l.info.tmin, mesh_f = l.mesh;
  if (mesh_f == kNone) return false;
  Patch F, B;
  if (!make_patch(c, s, mesh_f, -1, F) || !make_patch(c, s, mesh_f, +1, B)) return false;
  if (!(F.tmin >= 0) || !(B.tmax <= 1) || !after(F, B, 0)) return false;
  const double gap = ExitDepthRay::kTouchDouble * 1.0 * (1 + 0x1p-40);  // canonical_interval(..., 1.0)
  uint32_t mesh_g = kNone;
  for (const Live& l : s.live) {
    if (!l.closed || l.mesh == mesh_f || l.sigma >= 0 || after(B, patch_of(l.info), gap)) continue;
    if (mesh_g != kNone && mesh_g != l.mesh) return false;
    mesh_g = l.mesh;
  }
  Patch G, B2;
  if (mesh_g != kNone) {
    if (!make_patch(c, s, mesh_g, -1, G) || !make_patch(c, s, mesh_g, +1, B2)) return false;
    if (!after(F, G, 0) || !after(G, B2, 0) || !(B2.tmax <= 1)) return false;
  }
  for (const Live& l : s.live) {
    if (l.closed && (l.mesh == mesh_f || l.mesh == mesh_g)) continue;
    const Patch o = patch_of(l.info);
    if (l.closed ? !after(B, o, gap) || (mesh_g != kNone && !after(B2, o, gap)) : !after(F, o, 0)) return false;
  }
  const float a = canonical_depth(light, F.tmax), b = canonical_depth(light, B.tmin);
  if (!(a <= b)) return false;
  iv = Interval{a, b};
  return true;
}

// The static rule's open layer (raster_bounds.hpp "static"). The layer grows from the
// nearest live candidate by every candidate not provably after it (scalar bounds first,
// then the corner test of after(Patch, ...), redone until nothing joins, since the layer's
// depths widen as it grows); a closed member, a member facing the other way or more than
// kMaxLayer members end the proof. Then (1) cover_once(): each texel centre is covered by
// exactly one member, so its hit list starts with that member's hit (every non-member is
// after the layer at every texel, and t in [0, 1] is checked), which is open: lo is its
// depth, at most the layer's largest depth a; (2) every later hit is a non-member's, whose
// t is at least their smallest padded bound bt, so the smallest depth above lo is at
// least depth(bt) and hi, just below it (or 1), is at least b = depth(bt) less one ulp
// (1 when bt > 1: nothing else can be hit). [a, b] then lies inside [lo, hi].
bool RasterBounds::Impl::classify_open(const Corners& c, Scratch& s, Interval& iv) const {
  const size_t n = s.live.size();
  if (n == 0) return false;
  uint32_t first = 0;
  for (uint32_t i = 1; i < n; ++i)
    if (s.live[i].info.tmin < s.live[first].info.tmin) first = i;
  const Live& f = s.live[first];
  if (f.closed || f.sigma == 0 || !(f.info.tmin >= 0)) return false;
  s.in_layer.assign(n, 0);
  s.in_layer[first] = 1;
  s.members.assign(1, first);
  Patch P = patch_of(f.info);
  for (bool grew = true; grew;) {
    grew = false;
    for (uint32_t i = 0; i < n; ++i) {
      if (s.in_layer[i]) continue;
      const Live& l = s.live[i];
      if (l.info.tmin > P.tmax || after(P, patch_of(l.info), 0)) continue;
      if (l.closed || l.sigma != f.sigma || s.members.size() >= kMaxLayer) return false;
      s.in_layer[i] = 1;
      s.members.push_back(i);
      for (int q = 0; q < 4; ++q) P.lo[q] = std::min(P.lo[q], l.info.t[q]), P.hi[q] = std::max(P.hi[q], l.info.t[q]);
      P.pad = std::max(P.pad, l.info.pad), P.tmin = std::min(P.tmin, l.info.tmin), P.tmax = std::max(P.tmax, l.info.tmax);
      grew = true;
    }
  }
  if (!(P.tmin >= 0) || !(P.tmax <= 1)) return false;
  Patch covered;
  if (!cover_once(c, s, f.sigma, covered)) return false;
  double bt = INFINITY;
  for (uint32_t i = 0; i < n; ++i)
    if (!s.in_layer[i]) bt = std::min(bt, s.live[i].info.tmin);
  const float a = canonical_depth(light, P.tmax);
  const float b = bt > 1 ? kLitDepth : std::nextafter(canonical_depth(light, bt), -INFINITY);
  if (!(a <= b)) return false;
  iv = Interval{a, b};
  return true;
}

std::optional<Interval> RasterBounds::Impl::region_interval(uint32_t level, uint64_t x0, uint64_t y0,
                                                            uint64_t side) const {
  const std::vector<Candidate> cand = candidates({level, x0, y0, uint32_t(side), uint32_t(side)});
  Scratch& s = scratch.local();
  s.setup_ids.clear();
  for (const Candidate& cd : cand) s.setup_ids.push_back(cd.setup);
  // The corner texels' origins, operation for operation as tile() computes them.
  Corners c;
  {
    const double inv = std::ldexp(1.0, -int(level)), E = light.extent_uv();
    const Vec3d org = light.origin(), au = light.axis_u(), av = light.axis_v();
    const Vec3d fn = light.ray_axis() * light.near_plane();
    const uint64_t xs[4] = {x0, x0 + side - 1, x0, x0 + side - 1}, ys[4] = {y0, y0, y0 + side - 1, y0 + side - 1};
    for (int q = 0; q < 4; ++q) {
      const Vec3d o = org + au * ((double(xs[q]) + 0.5) * inv * E) + av * ((double(ys[q]) + 0.5) * inv * E) + fn - centre;
      c.ox[q] = o.x, c.oy[q] = o.y, c.oz[q] = o.z;
    }
  }
  Interval iv;
  if (classify(c, s.setup_ids, true, s, iv)) return iv;
  // Every candidate misses every texel centre: nothing is hit, every texel is lit.
  if (s.known && s.cover.empty()) return Interval{kLitDepth, kLitDepth};
  return std::nullopt;
}

Interval RasterBounds::Impl::texel_reference(uint32_t level, uint64_t x, uint64_t y) const {
  const LightRay ray = light.texel_ray(level, x, y);
  const Vec3d o = ray.origin - centre;
  const CoverageRay r = CoverageRay::of(o, ray.dir);
  std::vector<CanonicalHit> hits;
  for (uint32_t t = 0; t < tri.size(); ++t) {
    const Vec3d& a = v[tri[t][0]];
    const Vec3d& b = v[tri[t][1]];
    const Vec3d& c = v[tri[t][2]];
    const int f = canonical_cover(r, a, b, c);
    if (f == 0) continue;
    const double tp = CanonicalPlane::of(a, b, c).t(o, ray.dir, NAN);
    if (!std::isfinite(tp) || tp < 0 || tp > 1) continue;
    hits.push_back(CanonicalHit{tp, t, mesh[t], int8_t(f), closed[t] != 0});
  }
  std::sort(hits.begin(), hits.end());
  const CanonicalResult res = canonical_interval(hits, 1.0);
  const Interval iv = canonical_depths(light, res);
  if (static_rule && !hits.empty() && !res.fell_back && iv.hi == iv.lo)
    return widen_static(iv, next_depth_after(light, hits.data(), hits.size(), iv.lo));
  return iv;
}

const char* to_string(RasterSkip s) {
  switch (s) {
    case RasterSkip::off: return "off";
    case RasterSkip::exact: return "exact";
    case RasterSkip::narrow: return "narrow";
    case RasterSkip::regions: return "regions";
  }
  return "?";
}

RasterSkip parse_raster_skip(const std::string& text) {
  if (text == "off") return RasterSkip::off;
  if (text == "exact") return RasterSkip::exact;
  if (text == "narrow") return RasterSkip::narrow;
  if (text == "regions") return RasterSkip::regions;
  throw Error("--raster-skip: expected off, exact, narrow or regions, got '" + text + "'");
}

RasterBounds::RasterBounds(const Scene& scene, const LightSpace& light, RasterSkip skip, TraceMode mode)
    : impl_(std::make_unique<Impl>(scene, light)) {
  if (mode != TraceMode::bounds && mode != TraceMode::static_bounds)
    throw Error("raster builder: only the canonical bounds and the static-geometry interval are supported");
  impl_->skip = skip;
  impl_->static_rule = mode == TraceMode::static_bounds;
}
RasterSkip RasterBounds::skip() const { return impl_->skip; }
TraceMode RasterBounds::mode() const { return impl_->static_rule ? TraceMode::static_bounds : TraceMode::bounds; }
uint64_t RasterBounds::skipped_texels() const { return impl_->skipped.load(); }
RasterBounds::~RasterBounds() = default;

bool RasterBounds::traces_exit_depths() const { return impl_->any_closed; }
double RasterBounds::setup_seconds() const { return impl_->setup_s; }
uint64_t RasterBounds::triangle_count() const { return impl_->tri.size(); }

std::optional<Interval> RasterBounds::region_interval(uint32_t level, uint64_t x0, uint64_t y0,
                                                      uint64_t side) const {
  if (level > kMaxLevel || side == 0 || x0 >= (uint64_t(1) << level) || y0 >= (uint64_t(1) << level) ||
      side > (uint64_t(1) << level) - std::max(x0, y0))
    throw Error("raster builder: region " + std::to_string(x0) + "," + std::to_string(y0) + " of side " +
                std::to_string(side) + " leaves the level-" + std::to_string(level) + " map");
  return impl_->region_interval(level, x0, y0, side);
}

Interval RasterBounds::brute_force_texel(uint32_t level, uint64_t x, uint64_t y) const {
  return impl_->texel_reference(level, x, y);
}

IntervalTile RasterBounds::trace(const TraceRegion& region, DepthBoundsStats* stats,
                                 std::atomic<uint64_t>* progress) const {
  DepthBoundsTracer::check_region(region);
  const auto t_start = Clock::now();
  IntervalTile out;
  out.level = region.level;
  out.x0 = region.x0;
  out.y0 = region.y0;
  out.width = region.width;
  out.height = region.height;
  out.data.assign(size_t(region.width) * region.height, Interval{kLitDepth, kLitDepth});
  const uint32_t tx = (region.width + kTile - 1) / kTile, ty = (region.height + kTile - 1) / kTile;
  const std::vector<Candidate> cand = impl_->candidates(region);
  // Bin (counting sort): a candidate goes to every tile its texel box touches.
  std::vector<uint32_t> start(size_t(tx) * ty + 1, 0), cursor, ids;
  for (int pass = 0; pass < 2; ++pass) {
    for (uint32_t c = 0; c < cand.size(); ++c)
      for (int32_t j = cand[c].y0 / int32_t(kTile); j <= cand[c].y1 / int32_t(kTile); ++j)
        for (int32_t i = cand[c].x0 / int32_t(kTile); i <= cand[c].x1 / int32_t(kTile); ++i) {
          const size_t b = size_t(j) * tx + size_t(i);
          if (pass == 0) ++start[b + 1];
          else ids[cursor[b]++] = c;
        }
    if (pass == 0) {
      for (size_t b = 0; b + 1 < start.size(); ++b) start[b + 1] += start[b];
      ids.resize(start.back());
      cursor.assign(start.begin(), start.end() - 1);
    }
  }
  auto bin_begin = [&](size_t b) { return size_t(start[b]); };
  auto bin_end = [&](size_t b) { return size_t(start[b + 1]); };
  std::atomic<uint64_t> hits{0}, closed{0}, fallbacks{0}, tests{0};
  uint64_t empty_texels = 0;
  for (size_t b = 0; b + 1 < start.size(); ++b)
    if (bin_begin(b) == bin_end(b)) {
      const uint32_t bi = uint32_t(b % tx) * kTile, bj = uint32_t(b / tx) * kTile;
      empty_texels += uint64_t(std::min(kTile, region.width - bi)) * std::min(kTile, region.height - bj);
    }
  if (progress && empty_texels) progress->fetch_add(empty_texels, std::memory_order_relaxed);
  tbb::parallel_for(size_t(0), size_t(tx) * ty, [&](size_t b) {
    const size_t first = bin_begin(b), n = bin_end(b) - first;
    if (n == 0) return;  // nothing in the tile's prism: lit, no per-texel work
    const uint32_t bi = uint32_t(b % tx) * kTile, bj = uint32_t(b / tx) * kTile;
    DepthBoundsStats local;
    impl_->tile(region, cand.data(), ids.data() + first, n, bi, bj, out, local);
    hits += local.hits, closed += local.closed, fallbacks += local.fallbacks;
    tests += local.traversals;
    if (progress)
      progress->fetch_add(uint64_t(std::min(kTile, region.width - bi)) * std::min(kTile, region.height - bj),
                          std::memory_order_relaxed);
  });
  if (stats) {
    *stats = DepthBoundsStats{};
    stats->texels = stats->rays = uint64_t(region.width) * region.height;
    stats->traversals = tests, stats->hits = hits, stats->closed = closed, stats->fallbacks = fallbacks;
    stats->seconds = std::chrono::duration<double>(Clock::now() - t_start).count();
  }
  return out;
}

}  // namespace st
