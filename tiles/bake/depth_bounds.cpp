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
#include "tiles/bake/canonical_depth.hpp"
#include "tiles/bake/exit_depth.hpp"

namespace st {
namespace {

// Embree geometry ids: closed triangles and open triangles live in two geometries so a
// hit tells at once whether it counts (MH §3.1: open geometry gives hi = lo).
constexpr unsigned kClosedGeom = 0, kOpenGeom = 1;

// The widest packet (rtcIntersect16); the default is 8 lanes over 2 rows x 4 columns of
// texels: rtcIntersect8 on coherent rays was the fastest Embree 3 query measured for
// these maps. The other shapes exist so that tests can prove the canonical depth does not
// depend on the batching (canonical_depth.hpp).
constexpr unsigned kMaxLanes = 16;

// What the canonical window traversal gathers per lane: the smallest canonical t of the
// primitives hit (canonical_depth.hpp step 4) and, for the static-geometry interval, the
// canonical t of every primitive in the window (up to kMaxWindow; more is an overflow).
struct CanonicalLane {
  static constexpr uint32_t kMaxWindow = 16;
  Vec3d origin, dir;  // recentred, double
  double min_t;
  double t[kMaxWindow];
  uint32_t n;
  bool overflow;
  void reset() { min_t = INFINITY, n = 0, overflow = false; }
};

// Embree passes our context pointer to the filter; RTCIntersectContext must come first.
// Each lane's counting state also holds what the filter gathers for it.
struct FilterContext {
  RTCIntersectContext ctx;
  const std::vector<CanonicalPlane>* planes;  // by geometry id, then primitive id
  ExitDepthRay lane[kMaxLanes];
  CanonicalLane canon[kMaxLanes];
};
static_assert(std::is_standard_layout_v<FilterContext>);

// Hands every candidate hit to its ray's counter, which accepts a smaller t (Embree then
// shrinks tfar to it) and rejects the rest; an equal t is recorded on the way, and since
// Embree's depth test is t <= tfar the other primitives at that t are reported too.
void offer_hits(const RTCFilterFunctionNArguments* args) {
  auto* fc = reinterpret_cast<FilterContext*>(args->context);
  const unsigned n = args->N;
  for (unsigned i = 0; i < n; ++i) {
    if (args->valid[i] == 0) continue;
    const unsigned lane = RTCRayN_id(args->ray, n, i);
    if (lane >= kMaxLanes) {  // never: we set every id; reject rather than index out of range
      args->valid[i] = 0;
      continue;
    }
    const bool closed = RTCHitN_geomID(args->hit, n, i) == kClosedGeom;
    const float t = RTCRayN_tfar(args->ray, n, i);
    if (!fc->lane[lane].offer(t, closed, RTCHitN_primID(args->hit, n, i))) args->valid[i] = 0;
  }
}

// The canonical window traversal: every hit is rejected (the traversal sees the whole
// window) and its primitive's canonical t kept if it is the smallest so far.
void gather_canonical(const RTCFilterFunctionNArguments* args) {
  auto* fc = reinterpret_cast<FilterContext*>(args->context);
  const unsigned n = args->N;
  for (unsigned i = 0; i < n; ++i) {
    if (args->valid[i] == 0) continue;
    args->valid[i] = 0;
    const unsigned lane = RTCRayN_id(args->ray, n, i);
    const unsigned geom = RTCHitN_geomID(args->hit, n, i);
    if (lane >= kMaxLanes || geom > kOpenGeom) continue;
    const std::vector<CanonicalPlane>& planes = fc->planes[geom];
    const unsigned prim = RTCHitN_primID(args->hit, n, i);
    if (prim >= planes.size()) continue;
    CanonicalLane& c = fc->canon[lane];
    const double t = planes[prim].t(c.origin, c.dir, RTCRayN_tfar(args->ray, n, i));
    c.min_t = std::min(c.min_t, t);
    if (c.n < CanonicalLane::kMaxWindow) c.t[c.n++] = t;
    else c.overflow = true;
  }
}

// One Embree query over packets of N rays, through one interface: RTCRayHit4/8/16 are
// structures of arrays; single rays (N = 1) go through rtcIntersect1 on a copy.
struct RayHit1 {
  struct {
    float org_x[1], org_y[1], org_z[1], tnear[1], dir_x[1], dir_y[1], dir_z[1], time[1],
        tfar[1];
    unsigned mask[1], id[1], flags[1];
  } ray;
  struct {
    unsigned geomID[1];
  } hit;
};
void intersect(const int* valid, RTCScene scene, RTCIntersectContext* ctx, RayHit1* p) {
  if (valid[0] == 0) return;
  RTCRayHit rh;
  rh.ray.org_x = p->ray.org_x[0], rh.ray.org_y = p->ray.org_y[0], rh.ray.org_z = p->ray.org_z[0];
  rh.ray.tnear = p->ray.tnear[0], rh.ray.tfar = p->ray.tfar[0], rh.ray.time = p->ray.time[0];
  rh.ray.dir_x = p->ray.dir_x[0], rh.ray.dir_y = p->ray.dir_y[0], rh.ray.dir_z = p->ray.dir_z[0];
  rh.ray.mask = p->ray.mask[0], rh.ray.id = p->ray.id[0], rh.ray.flags = p->ray.flags[0];
  rh.hit.geomID = p->hit.geomID[0];
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(scene, ctx, &rh);
  p->ray.tfar[0] = rh.ray.tfar;
  p->hit.geomID[0] = rh.hit.geomID;
}
void intersect(const int* valid, RTCScene scene, RTCIntersectContext* ctx, RTCRayHit4* p) {
  rtcIntersect4(valid, scene, ctx, p);
}
void intersect(const int* valid, RTCScene scene, RTCIntersectContext* ctx, RTCRayHit8* p) {
  rtcIntersect8(valid, scene, ctx, p);
}
void intersect(const int* valid, RTCScene scene, RTCIntersectContext* ctx, RTCRayHit16* p) {
  rtcIntersect16(valid, scene, ctx, p);
}

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
  ClosedFaces closed_faces;  // by primitive id of the closed geometry; planes relative to centre
  std::vector<CanonicalPlane> planes[2];  // canonical planes by geometry id and primitive id
  uint64_t triangles = 0;
  bool any_closed = false;
  double build_s = 0;

  ~Impl() {
    if (scene) rtcReleaseScene(scene);
    if (device) rtcReleaseDevice(device);
  }

  void build(const Scene& s);
  void mark_touchable(double scene_size);
  template <class RayHit, unsigned W, unsigned H>
  void trace_packet(const TraceRegion& r, uint32_t px, uint32_t py, TraceMode mode,
                    IntervalTile& out, DepthBoundsStats& st) const;
  template <class RayHit, unsigned kLanes>
  void extend_static(RayHit& rh, FilterContext& fc, const bool* used, Interval* iv,
                     DepthBoundsStats& st) const;
  template <class RayHit, unsigned W, unsigned H>
  void trace_rows(const TraceRegion& r, TraceMode mode, IntervalTile& tile,
                  std::atomic<uint64_t>* progress, DepthBoundsStats& total) const;
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
      planes[geom_id].push_back(CanonicalPlane::of(s.vertices[t[0]] - centre,
                                                   s.vertices[t[1]] - centre,
                                                   s.vertices[t[2]] - centre));
      if (closed) {
        const Vec3d& a = s.vertices[t[0]];
        const Vec3d normal = cross(s.vertices[t[1]] - a, s.vertices[t[2]] - a);
        Facing facing = Facing::per_ray;
        if (light.kind() == LightKind::sun) {  // one direction for every texel ray
          const double f = dot(normal, light.forward());
          facing = f < 0 ? Facing::front : (f > 0 ? Facing::back : Facing::edge_on);
        }
        closed_faces.add(tri_mesh[i], facing, normal, dot(normal, a - centre));
      }
      ++k;
    }
    rtcCommitGeometry(g);
    rtcAttachGeometryByID(scene, g, geom_id);
    rtcReleaseGeometry(g);
  }
  rtcReleaseBuffer(vbuf);
  any_closed = closed_faces.size() != 0;
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
  const size_t n = closed_faces.size();
  std::vector<Key> keys(n);
  std::vector<int8_t> orient(n, 0);
  std::unordered_map<Key, std::vector<Side>, KeyHash> planes;
  planes.reserve(n / 2 + 1);
  for (size_t k = 0; k < n; ++k) {
    const Vec3d& nn = closed_faces.normal[k];
    const double len = length(nn);
    if (!(len > 0) || !std::isfinite(len)) continue;
    const Vec3d u = nn / len;
    const double ax = std::fabs(u.x), ay = std::fabs(u.y), az = std::fabs(u.z);
    const double major = ax >= ay && ax >= az ? u.x : (ay >= az ? u.y : u.z);
    const int8_t o = major > 0 ? 1 : -1;
    const double d = closed_faces.plane[k] / len * o / scene_size;
    keys[k] = {{std::llround(u.x * o * 0x1p24), std::llround(u.y * o * 0x1p24),
                std::llround(u.z * o * 0x1p24), std::llround(d * 0x1p32)}};
    orient[k] = o;
    auto& sides = planes[keys[k]];
    const uint32_t mesh = closed_faces.mesh(uint32_t(k));
    bool seen = false;
    for (const Side& sd : sides) seen |= sd.mesh == mesh && sd.orientation == o;
    if (!seen && sides.size() < 8) sides.push_back({mesh, o});
  }
  closed_faces.touchable.assign(n, 0);
  for (size_t k = 0; k < n; ++k) {
    if (orient[k] == 0) continue;
    const auto& sides = planes[keys[k]];
    if (sides.size() >= 8) {  // crowded plane: assume contact
      closed_faces.touchable[k] = 1;
      continue;
    }
    for (const Side& sd : sides)
      if (sd.mesh != closed_faces.mesh(uint32_t(k)) && sd.orientation != orient[k])
        closed_faces.touchable[k] = 1;
  }
}

template <class RayHit, unsigned W, unsigned H>
void DepthBoundsTracer::Impl::trace_packet(const TraceRegion& r, uint32_t px, uint32_t py,
                                           TraceMode mode, IntervalTile& out,
                                           DepthBoundsStats& st) const {
  constexpr unsigned kLanes = W * H;
  static_assert(kLanes <= kMaxLanes);
  alignas(64) RayHit rh;
  alignas(64) int valid[kLanes];
  FilterContext fc;
  rtcInitIntersectContext(&fc.ctx);
  fc.ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  fc.planes = planes;
  const bool counting = mode != TraceMode::first_hit && any_closed;
  const bool canonical = mode == TraceMode::bounds || mode == TraceMode::static_bounds;
  fc.ctx.filter = counting ? offer_hits : nullptr;

  const bool sun = light.kind() == LightKind::sun;
  const float t_min = sun ? 0.0f : float(light.near_plane());
  const float t_max = sun ? 1.0f : float(light.far_plane());

  bool active[kLanes], used[kLanes];
  uint32_t n_lanes = 0;
  for (unsigned l = 0; l < kLanes; ++l) {
    const uint32_t i = px * W + l % W, j = py * H + l / W;
    active[l] = used[l] = i < r.width && j < r.height;
    valid[l] = active[l] ? -1 : 0;
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
    rh.ray.org_x[l] = float(o.x), rh.ray.org_y[l] = float(o.y), rh.ray.org_z[l] = float(o.z);
    rh.ray.dir_x[l] = float(ray.dir.x), rh.ray.dir_y[l] = float(ray.dir.y);
    rh.ray.dir_z[l] = float(ray.dir.z);
    fc.lane[l].start(closed_faces, o, ray.dir, t_min, t_max);
    fc.canon[l].origin = o, fc.canon[l].dir = ray.dir;
    fc.canon[l].reset();
  }
  if (n_lanes == 0) return;
  st.rays += n_lanes;
  st.texels += n_lanes;

  // First traversal: the first hit for everyone, and the first group of hits for counting.
  intersect(valid, scene, &fc.ctx, &rh);
  st.traversals += n_lanes;
  uint32_t n_active = 0;
  bool any_hit = false;
  for (unsigned l = 0; l < kLanes; ++l) {
    if (!active[l]) continue;
    active[l] = false;
    valid[l] = 0;
    if (rh.hit.geomID[l] == RTC_INVALID_GEOMETRY_ID) continue;  // lit
    if (!counting) fc.lane[l].take_first_hit(rh.ray.tfar[l]);
    else active[l] = fc.lane[l].first_traversal_done();
    n_active += active[l];
    any_hit = true;
    valid[l] = -1;
  }

  // The canonical window (canonical_depth.hpp steps 1 and 4): every primitive hit within
  // kCanonicalWindow of the first hit, its canonical t, the smallest kept.
  if (canonical && any_hit) {
    const float w = float(kCanonicalWindow * (double(t_max) - t_min));
    uint32_t n_hit = 0;
    for (unsigned l = 0; l < kLanes; ++l) {
      if (valid[l] == 0) continue;
      ++n_hit;
      const float t = fc.lane[l].lo_t();
      rh.ray.tnear[l] = std::max(t_min, t - w);
      rh.ray.tfar[l] = std::min(t_max, t + w);
      rh.hit.geomID[l] = RTC_INVALID_GEOMETRY_ID;
    }
    fc.ctx.filter = gather_canonical;
    intersect(valid, scene, &fc.ctx, &rh);
    fc.ctx.filter = offer_hits;
    st.traversals += n_hit;
  }

  // The counters' further traversals, all lanes still counting in one packet.
  while (n_active > 0) {
    for (unsigned l = 0; l < kLanes; ++l) {
      valid[l] = active[l] ? -1 : 0;
      if (!active[l]) continue;
      rh.ray.tnear[l] = fc.lane[l].tnear();
      rh.ray.tfar[l] = fc.lane[l].tfar();
      rh.hit.geomID[l] = RTC_INVALID_GEOMETRY_ID;
    }
    intersect(valid, scene, &fc.ctx, &rh);
    st.traversals += n_active;
    for (unsigned l = 0; l < kLanes; ++l) {
      if (!active[l] || fc.lane[l].traversal_done()) continue;
      active[l] = false;
      --n_active;
    }
  }

  Interval iv[kLanes];
  for (unsigned l = 0; l < kLanes; ++l) {
    const ExitDepthRay& ray = fc.lane[l];
    iv[l] = Interval{kLitDepth, kLitDepth};
    if (!used[l]) continue;  // a lane outside the region: its state was never started
    iv[l] = ray.interval(light);
    if (!canonical || !ray.hit()) continue;
    // canonical_depth.hpp steps 4 and 5. The window normally reports the first hit
    // again; if it reported nothing, the tracer's t stands.
    const CanonicalLane& c = fc.canon[l];
    const double lo_t = std::isfinite(c.min_t) ? c.min_t : double(ray.lo_t());
    iv[l].lo = iv[l].hi = canonical_depth(light, lo_t);
    if (ray.hi_t() > ray.lo_t() && ray.exit_count() > 0) {
      double hi_t = -INFINITY;
      for (uint32_t k = 0; k < ray.exit_count(); ++k)
        hi_t = std::max(hi_t, planes[kClosedGeom][ray.exit_prim(k)].t(c.origin, c.dir, ray.hi_t()));
      iv[l].hi = std::max(iv[l].lo, canonical_depth(light, hi_t));
    }
  }
  if (mode == TraceMode::static_bounds) extend_static<RayHit, kLanes>(rh, fc, used, iv, st);

  for (unsigned l = 0; l < kLanes; ++l) {
    if (!used[l]) continue;
    const uint32_t i = px * W + l % W, j = py * H + l / W;
    const ExitDepthRay& ray = fc.lane[l];
    out.at(i, j) = iv[l];
    st.fallbacks += ray.fell_back();
    if (!ray.hit()) continue;
    ++st.hits;
    if (iv[l].hi > iv[l].lo) ++st.closed;
  }
}

// The static-geometry interval (voxel paper §6.1 "static geometry"): a receiver lies on a
// surface, never in the air between two, so a texel whose first hit is open (hi = lo) may
// store anything up to just below the depth of the next surface along its ray. The next
// surface is the nearest canonical depth above lo: among the first window's primitives,
// or the first hit past the window (found by a plain traversal) and its own canonical
// window. No surface behind: hi = 1. Closed first hits keep their exit depth; fallbacks
// and a crowded window keep hi = lo.
template <class RayHit, unsigned kLanes>
void DepthBoundsTracer::Impl::extend_static(RayHit& rh, FilterContext& fc, const bool* used,
                                            Interval* iv, DepthBoundsStats& st) const {
  const bool sun = light.kind() == LightKind::sun;
  const float t_min = sun ? 0.0f : float(light.near_plane());
  const float t_max = sun ? 1.0f : float(light.far_plane());
  const float w = float(kCanonicalWindow * (double(t_max) - t_min));
  alignas(64) int valid[kLanes];
  float next[kLanes];
  uint32_t n = 0;
  for (unsigned l = 0; l < kLanes; ++l) {
    const ExitDepthRay& ray = fc.lane[l];
    valid[l] = 0;
    next[l] = INFINITY;
    if (!used[l] || !ray.hit() || ray.fell_back() || iv[l].hi != iv[l].lo || fc.canon[l].overflow) continue;
    const CanonicalLane& c = fc.canon[l];
    for (uint32_t k = 0; k < c.n; ++k) {
      const float d = canonical_depth(light, c.t[k]);
      if (d > iv[l].lo) next[l] = std::min(next[l], d);
    }
    const float t0 = ray.lo_t() + w;
    if (t0 >= t_max) continue;
    valid[l] = -1;
    ++n;
    rh.ray.tnear[l] = t0;
    rh.ray.tfar[l] = t_max;
    rh.hit.geomID[l] = RTC_INVALID_GEOMETRY_ID;
  }
  if (n > 0) {
    fc.ctx.filter = nullptr;  // the plain first hit past the window
    intersect(valid, scene, &fc.ctx, &rh);
    st.traversals += n;
    n = 0;
    for (unsigned l = 0; l < kLanes; ++l) {
      if (valid[l] == 0) continue;
      if (rh.hit.geomID[l] == RTC_INVALID_GEOMETRY_ID) {
        valid[l] = 0;
        continue;
      }
      ++n;
      const float t = rh.ray.tfar[l];
      rh.ray.tnear[l] = std::max(t_min, t - w);
      rh.ray.tfar[l] = std::min(t_max, t + w);
      rh.hit.geomID[l] = RTC_INVALID_GEOMETRY_ID;
      fc.canon[l].reset();
    }
  }
  if (n > 0) {
    fc.ctx.filter = gather_canonical;
    intersect(valid, scene, &fc.ctx, &rh);
    st.traversals += n;
    for (unsigned l = 0; l < kLanes; ++l) {
      if (valid[l] == 0) continue;
      const CanonicalLane& c = fc.canon[l];
      for (uint32_t k = 0; k < c.n; ++k) {
        const float d = canonical_depth(light, c.t[k]);
        if (d > iv[l].lo) next[l] = std::min(next[l], d);
      }
    }
  }
  for (unsigned l = 0; l < kLanes; ++l) {
    const ExitDepthRay& ray = fc.lane[l];
    if (!used[l] || !ray.hit() || ray.fell_back() || iv[l].hi != iv[l].lo || fc.canon[l].overflow)
      continue;
    // Just below the next surface: the largest float < its depth (never below lo).
    iv[l].hi = next[l] == INFINITY ? kLitDepth
                                   : std::max(iv[l].lo, std::nextafter(next[l], -INFINITY));
  }
}

template <class RayHit, unsigned W, unsigned H>
void DepthBoundsTracer::Impl::trace_rows(const TraceRegion& r, TraceMode mode, IntervalTile& tile,
                                         std::atomic<uint64_t>* progress,
                                         DepthBoundsStats& total) const {
  const uint32_t rows = (r.height + H - 1) / H;
  const uint32_t cols = (r.width + W - 1) / W;
  std::atomic<uint64_t> rays{0}, traversals{0}, hits{0}, closed{0}, fallbacks{0}, texels{0};
  tbb::parallel_for(tbb::blocked_range<uint32_t>(0, rows), [&](const tbb::blocked_range<uint32_t>& br) {
    DepthBoundsStats local;
    for (uint32_t py = br.begin(); py != br.end(); ++py) {
      const uint64_t before = local.texels;
      for (uint32_t px = 0; px < cols; ++px) trace_packet<RayHit, W, H>(r, px, py, mode, tile, local);
      if (progress) progress->fetch_add(local.texels - before, std::memory_order_relaxed);
    }
    rays += local.rays, traversals += local.traversals, hits += local.hits;
    closed += local.closed, fallbacks += local.fallbacks, texels += local.texels;
  });
  total.texels = texels, total.rays = rays, total.traversals = traversals;
  total.hits = hits, total.closed = closed, total.fallbacks = fallbacks;
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
                                      std::atomic<uint64_t>* progress,
                                      PacketShape packet) const {
  check_region(r);
  const auto t_start = std::chrono::steady_clock::now();
  IntervalTile tile;
  tile.level = r.level, tile.x0 = r.x0, tile.y0 = r.y0;
  tile.width = r.width, tile.height = r.height;
  tile.data.assign(size_t(r.width) * r.height, Interval{});
  DepthBoundsStats local;
  switch (packet) {
    case PacketShape::single: impl_->trace_rows<RayHit1, 1, 1>(r, mode, tile, progress, local); break;
    case PacketShape::x4y1: impl_->trace_rows<RTCRayHit4, 4, 1>(r, mode, tile, progress, local); break;
    case PacketShape::x4y2: impl_->trace_rows<RTCRayHit8, 4, 2>(r, mode, tile, progress, local); break;
    case PacketShape::x8y1: impl_->trace_rows<RTCRayHit8, 8, 1>(r, mode, tile, progress, local); break;
    case PacketShape::x4y4: impl_->trace_rows<RTCRayHit16, 4, 4>(r, mode, tile, progress, local); break;
    case PacketShape::x16y1: impl_->trace_rows<RTCRayHit16, 16, 1>(r, mode, tile, progress, local); break;
  }
  if (stats) {
    *stats = local;
    stats->seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
  }
  return tile;
}

}  // namespace st
