// Dual depth bounds with Embree 3: see depth_bounds.hpp for the contract.
#include "tiles/bake/depth_bounds.hpp"

#include <embree3/rtcore.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <string>
#include <unordered_map>
#include <vector>

#include "common/error.hpp"

namespace st {
namespace {

// Embree geometry ids: closed triangles and open triangles live in two geometries so a
// hit tells at once whether it counts (MH §3.1: open geometry gives hi = lo).
constexpr unsigned kClosedGeom = 0, kOpenGeom = 1;

// Packets: 8 lanes over 2 rows x 4 columns of texels (ARCHITECTURE.md "Measured on the development machines": rtcIntersect8 on
// coherent rays is the fastest Embree 3 query here).
constexpr unsigned kLanes = 8, kPacketW = 4, kPacketH = 2;

// Per-ray table bounds; exceeding one makes the ray fall back to hi = lo (conservative).
constexpr uint32_t kMaxGroup = 16;       // hits at one exactly equal t
constexpr uint32_t kMaxDone = 48;        // primitives already processed on one ray
constexpr uint32_t kMaxMeshes = 16;      // closed meshes one ray is inside at once
constexpr uint32_t kMaxTraversals = 64;  // traversals per ray

// Embree's float t is not exact, and neither is its box culling: a triangle whose float
// t lies an ulp below the accepted hit can be culled in that traversal and then fall
// below the next traversal's tnear (seen on the city: ground top vs building bottom).
// So re-traces start kBackoff * t_range before the last group (processed primitives are
// excluded by id, so nothing is counted twice), and after the counters reach 0 at float
// t1 a look-ahead gathers every unprocessed closed hit in t1 +- kLookAhead * t_range
// (wide enough for float error on big triangles); such a hit counts as touching the exit
// (a box standing on another) only if its exact ray-plane t in double is within
// kTouchDouble * t_range of the exit's.
constexpr float kBackoff = 16.0f / (1 << 24);
constexpr float kLookAhead = 1.0f / (1 << 13);
constexpr double kTouchDouble = 1e-9;

constexpr float kNoHit = std::numeric_limits<float>::infinity();

// What the intersection filter gathers for one ray during one traversal: the smallest t
// not yet processed and every primitive hit at exactly that t.
struct LaneHits {
  float best_t;
  uint32_t n_group;
  uint32_t n_done;
  bool overflow;
  bool window;  // look-ahead: record every unprocessed hit up to tfar, accept none
  uint64_t group[kMaxGroup];
  uint64_t done[kMaxDone];  // primitives of earlier groups: never counted twice
};

// Embree passes our context pointer to the filter; RTCIntersectContext must come first.
struct FilterContext {
  RTCIntersectContext ctx;
  LaneHits lane[kLanes];
};
static_assert(std::is_standard_layout_v<FilterContext>);

inline uint64_t hit_key(unsigned geom, unsigned prim) { return (uint64_t(geom) << 32) | prim; }

inline bool contains(const uint64_t* keys, uint32_t n, uint64_t key) {
  for (uint32_t i = 0; i < n; ++i)
    if (keys[i] == key) return true;
  return false;
}

// Collects the full group of hits at the smallest t: a smaller t is accepted (Embree
// then shrinks tfar to it); an equal t is recorded and rejected, so traversal goes on
// and reports the other primitives at that t too (Embree's depth test is t <= tfar).
void collect_equal_t(const RTCFilterFunctionNArguments* args) {
  auto* fc = reinterpret_cast<FilterContext*>(args->context);
  const unsigned n = args->N;
  for (unsigned i = 0; i < n; ++i) {
    if (args->valid[i] == 0) continue;
    const unsigned lane = RTCRayN_id(args->ray, n, i);
    if (lane >= kLanes) {  // never: we set every id; reject rather than index out of range
      args->valid[i] = 0;
      continue;
    }
    LaneHits& h = fc->lane[lane];
    const float t = RTCRayN_tfar(args->ray, n, i);
    const uint64_t key = hit_key(RTCHitN_geomID(args->hit, n, i), RTCHitN_primID(args->hit, n, i));
    if (contains(h.done, h.n_done, key)) {
      args->valid[i] = 0;
    } else if (h.window) {
      if (!contains(h.group, h.n_group, key)) {
        if (h.n_group < kMaxGroup) h.group[h.n_group++] = key;
        else h.overflow = true;
      }
      args->valid[i] = 0;  // never shrink tfar: the whole window is searched
    } else if (t < h.best_t) {
      h.best_t = t;
      h.group[0] = key;
      h.n_group = 1;
      h.overflow = false;  // accepted: tfar becomes t
    } else {
      if (t == h.best_t && !contains(h.group, h.n_group, key)) {
        if (h.n_group < kMaxGroup) h.group[h.n_group++] = key;
        else h.overflow = true;
      }
      args->valid[i] = 0;
    }
  }
}

// Host-side counting state of one ray.
struct LaneCount {  // plain data: trace_packet resets n_mesh and total per ray
  uint32_t n_mesh;
  int32_t total;
  uint32_t mesh[kMaxMeshes];
  int32_t count[kMaxMeshes];
};


}  // namespace

DepthBoundsStats& DepthBoundsStats::operator+=(const DepthBoundsStats& o) {
  texels += o.texels, rays += o.rays, traversals += o.traversals, hits += o.hits;
  closed += o.closed, fallbacks += o.fallbacks, seconds += o.seconds;
  return *this;
}

struct DepthBoundsTracer::Impl {
  LightSpace light;
  Vec3d centre;
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  // closed prim -> (scene mesh index << 2) | facing code: one 4-byte random read per hit.
  // Facing codes: 0 front (+1), 1 back (-1), 2 edge-on (0), 3 depends on the ray (spot).
  std::vector<uint32_t> closed_info;
  std::vector<Vec3d> closed_normal;   // closed prim -> geometric normal (double, outwards)
  std::vector<double> closed_plane;   // closed prim -> dot(normal, v0 - centre)
  // closed prim -> 1 when a closed prim of another mesh lies in the same plane facing the
  // other way (a possible touching contact); exits through other prims need no look-ahead.
  std::vector<uint8_t> closed_touchable;
  uint64_t triangles = 0;
  bool any_closed = false;
  double build_s = 0;

  ~Impl() {
    if (scene) rtcReleaseScene(scene);
    if (device) rtcReleaseDevice(device);
  }

  void build(const Scene& s);
  void mark_touchable(double scene_size);
  void trace_packet(const TraceRegion& r, uint32_t px, uint32_t py, TraceMode mode,
                    IntervalTile& out, DepthBoundsStats& st) const;
  bool apply_group(const LaneHits& h, const Vec3d& dir, LaneCount& c,
                   uint32_t& closed_hits) const;
  float depth_of(float t) const;
  // Exact ray parameter of the plane of closed prim `prim` (double, recentred origin).
  double plane_t(uint32_t prim, const Vec3d& origin_c, const Vec3d& dir) const {
    const Vec3d& n = closed_normal[prim];
    return (closed_plane[prim] - dot(n, origin_c)) / dot(n, dir);
  }
};

namespace {

std::string embree_error(RTCDevice d) {
  switch (d ? rtcGetDeviceError(d) : rtcGetDeviceError(nullptr)) {
    case RTC_ERROR_NONE: return "none";
    case RTC_ERROR_INVALID_ARGUMENT: return "invalid argument";
    case RTC_ERROR_INVALID_OPERATION: return "invalid operation";
    case RTC_ERROR_OUT_OF_MEMORY: return "out of memory";
    case RTC_ERROR_UNSUPPORTED_CPU: return "unsupported CPU";
    case RTC_ERROR_CANCELLED: return "cancelled";
    default: return "unknown error";
  }
}

}  // namespace

void DepthBoundsTracer::Impl::build(const Scene& s) {
  const auto t_start = std::chrono::steady_clock::now();
  const size_t nv = s.vertices.size(), nt = s.triangles.size();
  if (nt > std::numeric_limits<uint32_t>::max() / 4 || s.meshes.size() >= (size_t(1) << 30))
    throw Error("depth bounds: scene '" + s.name + "' has too many triangles for Embree");
  // Which triangles are closed (meshes partition the triangles; anything else is open).
  std::vector<uint8_t> is_closed(nt, 0);
  for (size_t m = 0; m < s.meshes.size(); ++m) {
    const Mesh& mesh = s.meshes[m];
    if (uint64_t(mesh.first_triangle) + mesh.triangle_count > nt)
      throw Error("depth bounds: scene '" + s.name + "' mesh " + std::to_string(m) + " ('" +
                  mesh.name + "') references triangles past the end");
    if (mesh.closed)
      for (uint32_t i = 0; i < mesh.triangle_count; ++i) is_closed[mesh.first_triangle + i] = 1;
  }
  std::vector<uint32_t> tri_mesh(nt, 0);
  for (size_t m = 0; m < s.meshes.size(); ++m)
    for (uint32_t i = 0; i < s.meshes[m].triangle_count; ++i)
      tri_mesh[s.meshes[m].first_triangle + i] = uint32_t(m);
  for (size_t i = 0; i < nt; ++i)
    for (uint32_t v : s.triangles[i]) {
      if (v >= nv)
        throw Error("depth bounds: scene '" + s.name + "' triangle " + std::to_string(i) +
                    " references vertex " + std::to_string(v) + " of " + std::to_string(nv));
      if (!is_finite(s.vertices[v]))
        throw Error("depth bounds: scene '" + s.name + "' vertex " + std::to_string(v) +
                    " is not finite");
    }
  Aabb b = s.bounds();
  centre = b.empty() ? Vec3d{} : b.center();
  triangles = nt;

  device = rtcNewDevice(nullptr);
  if (!device) throw Error("embree: cannot create a device: " + embree_error(nullptr));
  scene = rtcNewScene(device);
  // Robust: watertight edges between neighbouring triangles (a ray through a shared edge
  // must not slip between them, or the counter would miss a face).
  rtcSetSceneFlags(scene, RTCSceneFlags(RTC_SCENE_FLAG_ROBUST |
                                        RTC_SCENE_FLAG_CONTEXT_FILTER_FUNCTION));
  rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_MEDIUM);

  // One shared vertex buffer, recentred in double then rounded to float. Embree reads 16
  // bytes per vertex, so pad the end by one float.
  RTCBuffer vbuf = rtcNewBuffer(device, nv * 3 * sizeof(float) + sizeof(float));
  if (!vbuf) throw Error("embree: cannot allocate the vertex buffer: " + embree_error(device));
  auto* vp = static_cast<float*>(rtcGetBufferData(vbuf));
  for (size_t i = 0; i < nv; ++i) {
    Vec3d p = s.vertices[i] - centre;
    vp[3 * i] = float(p.x), vp[3 * i + 1] = float(p.y), vp[3 * i + 2] = float(p.z);
  }
  vp[3 * nv] = 0;

  for (unsigned geom_id : {kClosedGeom, kOpenGeom}) {
    const bool closed = geom_id == kClosedGeom;
    size_t count = 0;
    for (size_t i = 0; i < nt; ++i) count += (is_closed[i] != 0) == closed;
    if (count == 0) continue;
    RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
    rtcSetGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, vbuf, 0,
                         3 * sizeof(float), nv);
    auto* ip = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
        g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), count));
    if (!ip) {
      rtcReleaseGeometry(g);
      rtcReleaseBuffer(vbuf);
      throw Error("embree: cannot allocate an index buffer: " + embree_error(device));
    }
    size_t k = 0;
    for (size_t i = 0; i < nt; ++i) {
      if ((is_closed[i] != 0) != closed) continue;
      const auto& t = s.triangles[i];
      ip[3 * k] = t[0], ip[3 * k + 1] = t[1], ip[3 * k + 2] = t[2];
      if (closed) {
        const Vec3d& a = s.vertices[t[0]];
        closed_normal.push_back(cross(s.vertices[t[1]] - a, s.vertices[t[2]] - a));
        uint32_t code = 3;
        if (light.kind() == LightKind::sun) {  // one direction for every texel ray
          const double f = dot(closed_normal.back(), light.forward());
          code = f < 0 ? 0 : (f > 0 ? 1 : 2);
        }
        closed_info.push_back(tri_mesh[i] << 2 | code);
        closed_plane.push_back(dot(closed_normal.back(), a - centre));
      }
      ++k;
    }
    rtcCommitGeometry(g);
    rtcAttachGeometryByID(scene, g, geom_id);
    rtcReleaseGeometry(g);
  }
  rtcReleaseBuffer(vbuf);
  any_closed = !closed_info.empty();
  mark_touchable(b.empty() ? 1.0 : std::max({b.extent().x, b.extent().y, b.extent().z, 1e-300}));
  rtcCommitScene(scene);
  if (rtcGetDeviceError(device) != RTC_ERROR_NONE)
    throw Error("embree: building the scene '" + s.name + "' failed: " + embree_error(device));
  build_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
}

// Coplanar, oppositely facing closed prims of different meshes (a box standing on
// another). Planes are keyed by the unit normal turned to a canonical orientation and the
// plane offset, quantised; two prims of one exact plane share a key. A pair that lands in
// neighbouring cells is missed, which only costs compression: without the look-ahead the
// exit is reported where the counters first reach 0 (conservative).
void DepthBoundsTracer::Impl::mark_touchable(double scene_size) {
  struct Key {
    int64_t q[4];
    bool operator==(const Key& o) const {
      return q[0] == o.q[0] && q[1] == o.q[1] && q[2] == o.q[2] && q[3] == o.q[3];
    }
  };
  struct KeyHash {
    size_t operator()(const Key& k) const {
      uint64_t h = 1469598103934665603ull;
      for (int64_t v : k.q) h = (h ^ uint64_t(v)) * 1099511628211ull;
      return size_t(h);
    }
  };
  struct Side {
    uint32_t mesh;
    int8_t orientation;
  };
  const size_t n = closed_info.size();
  std::vector<Key> keys(n);
  std::vector<int8_t> orient(n, 0);
  std::unordered_map<Key, std::vector<Side>, KeyHash> planes;
  planes.reserve(n / 2 + 1);
  for (size_t k = 0; k < n; ++k) {
    const Vec3d& nn = closed_normal[k];
    const double len = length(nn);
    if (!(len > 0) || !std::isfinite(len)) continue;
    const Vec3d u = nn / len;
    const double ax = std::fabs(u.x), ay = std::fabs(u.y), az = std::fabs(u.z);
    const double major = ax >= ay && ax >= az ? u.x : (ay >= az ? u.y : u.z);
    const int8_t o = major > 0 ? 1 : -1;
    const double d = closed_plane[k] / len * o / scene_size;
    keys[k] = {{std::llround(u.x * o * 0x1p24), std::llround(u.y * o * 0x1p24),
                std::llround(u.z * o * 0x1p24), std::llround(d * 0x1p32)}};
    orient[k] = o;
    auto& sides = planes[keys[k]];
    const uint32_t mesh = closed_info[k] >> 2;
    bool seen = false;
    for (const Side& sd : sides) seen |= sd.mesh == mesh && sd.orientation == o;
    if (!seen && sides.size() < 8) sides.push_back({mesh, o});
  }
  closed_touchable.assign(n, 0);
  for (size_t k = 0; k < n; ++k) {
    if (orient[k] == 0) continue;
    const auto& sides = planes[keys[k]];
    if (sides.size() >= 8) {  // crowded plane: assume contact
      closed_touchable[k] = 1;
      continue;
    }
    for (const Side& sd : sides)
      if (sd.mesh != closed_info[k] >> 2 && sd.orientation != orient[k]) closed_touchable[k] = 1;
  }
}

float DepthBoundsTracer::Impl::depth_of(float t) const {
  double d = light.kind() == LightKind::sun
                 ? double(t)
                 : (double(t) - light.near_plane()) / (light.far_plane() - light.near_plane());
  return float(std::clamp(d, 0.0, 1.0));
}

// Applies one group of equal-t hits to a ray's per-mesh counters (MH §3; voxel §6.1).
// Returns false when the counters can no longer be trusted; `closed_hits` receives the
// number of closed-geometry hits in the group (open ones are ignored).
bool DepthBoundsTracer::Impl::apply_group(const LaneHits& h, const Vec3d& dir, LaneCount& c,
                                          uint32_t& closed_hits) const {
  closed_hits = 0;
  if (h.overflow) return false;
  // Per mesh: sign of the summed facings, so two triangles of one mesh reported at a
  // shared edge count once, and a silhouette edge (front + back) counts zero.
  uint32_t meshes[kMaxGroup];
  int32_t sums[kMaxGroup];
  uint32_t n = 0;
  for (uint32_t i = 0; i < h.n_group; ++i) {
    if ((h.group[i] >> 32) != kClosedGeom) continue;  // open: ignored inside closed objects
    ++closed_hits;
    const uint32_t prim = uint32_t(h.group[i]);
    const uint32_t info = closed_info[prim], m = info >> 2;
    int32_t facing = (info & 3) == 0 ? 1 : ((info & 3) == 1 ? -1 : 0);
    if ((info & 3) == 3) {
      const double f = dot(closed_normal[prim], dir);
      facing = f < 0 ? 1 : (f > 0 ? -1 : 0);  // against the outward normal: entering
    }
    uint32_t j = 0;
    while (j < n && meshes[j] != m) ++j;
    if (j == n) meshes[n] = m, sums[n] = 0, ++n;
    sums[j] += facing;
  }
  for (uint32_t j = 0; j < n; ++j) {
    const int32_t net = std::clamp(sums[j], -1, 1);
    if (net == 0) continue;
    uint32_t k = 0;
    while (k < c.n_mesh && c.mesh[k] != meshes[j]) ++k;
    if (k == c.n_mesh) {
      if (net < 0 || c.n_mesh == kMaxMeshes) return false;
      c.mesh[k] = meshes[j], c.count[k] = 0, ++c.n_mesh;
    }
    c.count[k] += net;
    c.total += net;
    if (c.count[k] < 0) return false;  // never trust a negative counter
  }
  return true;
}

void DepthBoundsTracer::Impl::trace_packet(const TraceRegion& r, uint32_t px, uint32_t py,
                                           TraceMode mode, IntervalTile& out,
                                           DepthBoundsStats& st) const {
  alignas(64) RTCRayHit8 rh;
  alignas(32) int valid[kLanes];
  FilterContext fc;
  rtcInitIntersectContext(&fc.ctx);
  fc.ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  const bool counting = mode == TraceMode::bounds && any_closed;
  fc.ctx.filter = counting ? collect_equal_t : nullptr;

  const bool sun = light.kind() == LightKind::sun;
  const float t_min = sun ? 0.0f : float(light.near_plane());
  const float t_max = sun ? 1.0f : float(light.far_plane());

  Vec3d dirs[kLanes], origins[kLanes];
  float lo_t[kLanes], floor_t[kLanes] = {};
  bool active[kLanes];
  LaneCount counts[kLanes];
  uint32_t n_lanes = 0;
  for (unsigned l = 0; l < kLanes; ++l) {
    const uint32_t i = px * kPacketW + l % kPacketW, j = py * kPacketH + l / kPacketW;
    active[l] = i < r.width && j < r.height;
    valid[l] = active[l] ? -1 : 0;
    lo_t[l] = kNoHit;
    counts[l].n_mesh = 0, counts[l].total = 0;
    rh.ray.tnear[l] = t_min;
    rh.ray.tfar[l] = t_max;
    rh.ray.mask[l] = 0xFFFFFFFFu;
    rh.ray.id[l] = l;
    rh.ray.flags[l] = 0;
    rh.ray.time[l] = 0;
    rh.hit.geomID[l] = RTC_INVALID_GEOMETRY_ID;
    if (!active[l]) {
      rh.ray.org_x[l] = rh.ray.org_y[l] = rh.ray.org_z[l] = 0;
      rh.ray.dir_x[l] = rh.ray.dir_y[l] = 0, rh.ray.dir_z[l] = 1;
      continue;
    }
    ++n_lanes;
    LightRay ray = light.texel_ray(r.level, r.x0 + i, r.y0 + j);
    const Vec3d o = ray.origin - centre;
    dirs[l] = ray.dir;
    origins[l] = o;
    rh.ray.org_x[l] = float(o.x), rh.ray.org_y[l] = float(o.y), rh.ray.org_z[l] = float(o.z);
    rh.ray.dir_x[l] = float(ray.dir.x), rh.ray.dir_y[l] = float(ray.dir.y);
    rh.ray.dir_z[l] = float(ray.dir.z);
    LaneHits& h = fc.lane[l];
    h.best_t = kNoHit, h.n_group = 0, h.n_done = 0, h.overflow = false, h.window = false;
  }
  if (n_lanes == 0) return;
  st.rays += n_lanes;
  st.texels += n_lanes;

  // First traversal: lo for everyone, and the first group of hits for counting.
  rtcIntersect8(valid, scene, &fc.ctx, &rh);
  st.traversals += n_lanes;
  float hi_t[kLanes], exit_t[kLanes];  // exit_t: float t where the counters reached 0
  double exit_d[kLanes];               // its exact t (max over the exit group, double)
  uint32_t n_active = 0;
  for (unsigned l = 0; l < kLanes; ++l) {
    hi_t[l] = exit_t[l] = kNoHit;
    if (!active[l]) continue;
    if (rh.hit.geomID[l] == RTC_INVALID_GEOMETRY_ID) {
      active[l] = false;
      continue;
    }
    lo_t[l] = counting ? fc.lane[l].best_t : rh.ray.tfar[l];
    hi_t[l] = lo_t[l];
    active[l] = false;
    if (!counting) continue;
    LaneHits& h = fc.lane[l];
    uint32_t closed_hits = 0;
    if (!apply_group(h, dirs[l], counts[l], closed_hits) || h.n_group > kMaxDone) {
      ++st.fallbacks;  // e.g. the first closed hit is a back face: hi = lo
      continue;
    }
    // Open first hit (MH §3: hi = lo) or a grazing touch that enters nothing: hi = lo.
    if (closed_hits == 0 || counts[l].total == 0) continue;
    for (uint32_t k = 0; k < h.n_group; ++k) h.done[h.n_done++] = h.group[k];
    floor_t[l] = h.best_t;
    active[l] = true;
    ++n_active;
  }

  // Re-trace from tnear = the last group's t (inclusive; processed primitives are
  // excluded by id) until every counter is back to 0 (MH §3.1 depth peeling), then one
  // look-ahead confirms the exit or finds a touching entry (see kLookAhead).
  const float window = kLookAhead * (t_max - t_min);
  const float backoff = kBackoff * (t_max - t_min);
  const double touch = kTouchDouble * (double(t_max) - t_min);
  for (uint32_t pass = 1; n_active > 0; ++pass) {
    for (unsigned l = 0; l < kLanes; ++l) {
      valid[l] = active[l] ? -1 : 0;
      if (!active[l]) continue;
      LaneHits& h = fc.lane[l];
      h.window = exit_t[l] != kNoHit;
      rh.ray.tnear[l] = h.window ? std::max(t_min, exit_t[l] - window)
                                 : std::max(t_min, floor_t[l] - backoff);
      rh.ray.tfar[l] = h.window ? std::min(t_max, exit_t[l] + window) : t_max;
      rh.hit.geomID[l] = RTC_INVALID_GEOMETRY_ID;
      h.best_t = kNoHit, h.n_group = 0, h.overflow = false;
    }
    rtcIntersect8(valid, scene, &fc.ctx, &rh);
    st.traversals += n_active;
    for (unsigned l = 0; l < kLanes; ++l) {
      if (!active[l]) continue;
      LaneHits& h = fc.lane[l];
      bool trusted = h.n_done + h.n_group <= kMaxDone && !h.overflow, finished = false;
      if (h.window) {
        // Keep the closed hits whose exact t touches the exit; drop the rest (they lie
        // beyond a real gap and are found again by a later pass if we go on).
        uint32_t keep = 0;
        for (uint32_t k = 0; k < h.n_group; ++k) {
          if ((h.group[k] >> 32) != kClosedGeom) continue;
          if (plane_t(uint32_t(h.group[k]), origins[l], dirs[l]) <= exit_d[l] + touch)
            h.group[keep++] = h.group[k];
        }
        h.n_group = keep;
        if (trusted && keep == 0) {
          hi_t[l] = exit_t[l];  // confirmed: nothing touches the exit
          finished = true;
        }
      } else if (h.n_group == 0) {
        trusted = false;  // left the scene inside a closed object: do not trust it
      }
      if (!finished && trusted) {
        uint32_t closed_hits = 0;
        trusted = apply_group(h, dirs[l], counts[l], closed_hits) && pass + 1 < kMaxTraversals;
      }
      if (!finished && trusted) {
        for (uint32_t k = 0; k < h.n_group; ++k) h.done[h.n_done++] = h.group[k];
        if (h.window) {
          // Touching entry: inside again; resume from the exit (inclusive) so window hits
          // that did not touch are still met in order.
          if (counts[l].total > 0) floor_t[l] = exit_t[l], exit_t[l] = kNoHit;
        } else {
          floor_t[l] = h.best_t;
          if (counts[l].total == 0) {
            bool touchable = false;
            for (uint32_t k = 0; k < h.n_group; ++k)
              touchable |= (h.group[k] >> 32) == kClosedGeom &&
                           closed_touchable[uint32_t(h.group[k])] != 0;
            if (!touchable) {  // nothing can touch this exit: no look-ahead needed
              hi_t[l] = h.best_t;
              active[l] = false;
              --n_active;
              continue;
            }
            exit_t[l] = h.best_t;
            exit_d[l] = -INFINITY;
            for (uint32_t k = 0; k < h.n_group; ++k)
              if ((h.group[k] >> 32) == kClosedGeom)
                exit_d[l] = std::max(exit_d[l], plane_t(uint32_t(h.group[k]), origins[l], dirs[l]));
          }
        }
        continue;
      }
      if (!trusted) ++st.fallbacks;
      active[l] = false;
      --n_active;
    }
  }

  for (unsigned l = 0; l < kLanes; ++l) {
    const uint32_t i = px * kPacketW + l % kPacketW, j = py * kPacketH + l / kPacketW;
    if (i >= r.width || j >= r.height) continue;
    Interval& iv = out.at(i, j);
    if (lo_t[l] == kNoHit) {
      iv = Interval{kLitDepth, kLitDepth};
      continue;
    }
    iv.lo = depth_of(lo_t[l]);
    iv.hi = std::max(iv.lo, depth_of(hi_t[l]));
    ++st.hits;
    if (iv.hi > iv.lo) ++st.closed;
  }
}

DepthBoundsTracer::DepthBoundsTracer(const Scene& scene, const LightSpace& light)
    : impl_(std::make_unique<Impl>()) {
  impl_->light = light;
  impl_->build(scene);
}

DepthBoundsTracer::~DepthBoundsTracer() = default;

bool DepthBoundsTracer::traces_exit_depths() const { return impl_->any_closed; }
double DepthBoundsTracer::build_seconds() const { return impl_->build_s; }
uint64_t DepthBoundsTracer::triangle_count() const { return impl_->triangles; }

void DepthBoundsTracer::check_region(const TraceRegion& r) {
  if (r.level > kMaxLevel)
    throw Error("depth bounds: level " + std::to_string(r.level) + " exceeds the maximum " +
                std::to_string(kMaxLevel));
  const uint64_t side = uint64_t(1) << r.level;
  if (r.width == 0 || r.height == 0) throw Error("depth bounds: the region is empty");
  if (r.x0 >= side || r.y0 >= side || r.width > side - r.x0 || r.height > side - r.y0)
    throw Error("depth bounds: region " + std::to_string(r.x0) + "," + std::to_string(r.y0) +
                "," + std::to_string(r.width) + "," + std::to_string(r.height) +
                " leaves the " + std::to_string(side) + "^2 map");
  if (uint64_t(r.width) * r.height > kMaxRegionTexels)
    throw Error("depth bounds: region " + std::to_string(r.width) + "x" +
                std::to_string(r.height) + " exceeds 8192^2 texels per call; trace it in parts");
}

IntervalTile DepthBoundsTracer::trace(const TraceRegion& r, TraceMode mode,
                                      DepthBoundsStats* stats,
                                      std::atomic<uint64_t>* progress) const {
  check_region(r);
  const auto t_start = std::chrono::steady_clock::now();
  IntervalTile tile;
  tile.level = r.level, tile.x0 = r.x0, tile.y0 = r.y0;
  tile.width = r.width, tile.height = r.height;
  tile.data.assign(size_t(r.width) * r.height, Interval{});
  const uint32_t rows = (r.height + kPacketH - 1) / kPacketH;
  const uint32_t cols = (r.width + kPacketW - 1) / kPacketW;
  std::atomic<uint64_t> rays{0}, traversals{0}, hits{0}, closed{0}, fallbacks{0}, texels{0};
  tbb::parallel_for(tbb::blocked_range<uint32_t>(0, rows), [&](const tbb::blocked_range<uint32_t>& br) {
    DepthBoundsStats local;
    for (uint32_t py = br.begin(); py != br.end(); ++py) {
      const uint64_t before = local.texels;
      for (uint32_t px = 0; px < cols; ++px) impl_->trace_packet(r, px, py, mode, tile, local);
      if (progress) progress->fetch_add(local.texels - before, std::memory_order_relaxed);
    }
    rays += local.rays, traversals += local.traversals, hits += local.hits;
    closed += local.closed, fallbacks += local.fallbacks, texels += local.texels;
  });
  if (stats) {
    *stats = DepthBoundsStats{};
    stats->texels = texels, stats->rays = rays, stats->traversals = traversals;
    stats->hits = hits, stats->closed = closed, stats->fallbacks = fallbacks;
    stats->seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
  }
  return tile;
}

}  // namespace st
