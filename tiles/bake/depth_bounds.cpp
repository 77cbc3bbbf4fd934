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
#include "tiles/bake/exit_depth.hpp"

namespace st {
namespace {

// Embree geometry ids: closed triangles and open triangles live in two geometries so a
// hit tells at once whether it counts (MH §3.1: open geometry gives hi = lo).
constexpr unsigned kClosedGeom = 0, kOpenGeom = 1;

// Packets: 8 lanes over 2 rows x 4 columns of texels: rtcIntersect8 on coherent rays
// was the fastest Embree 3 query measured for these maps.
constexpr unsigned kLanes = 8, kPacketW = 4, kPacketH = 2;

// Embree passes our context pointer to the filter; RTCIntersectContext must come first.
// Each lane's counting state also holds what the filter gathers for it.
struct FilterContext {
  RTCIntersectContext ctx;
  ExitDepthRay lane[kLanes];
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
    if (lane >= kLanes) {  // never: we set every id; reject rather than index out of range
      args->valid[i] = 0;
      continue;
    }
    const bool closed = RTCHitN_geomID(args->hit, n, i) == kClosedGeom;
    const float t = RTCRayN_tfar(args->ray, n, i);
    if (!fc->lane[lane].offer(t, closed, RTCHitN_primID(args->hit, n, i))) args->valid[i] = 0;
  }
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

void DepthBoundsTracer::Impl::trace_packet(const TraceRegion& r, uint32_t px, uint32_t py,
                                           TraceMode mode, IntervalTile& out,
                                           DepthBoundsStats& st) const {
  alignas(64) RTCRayHit8 rh;
  alignas(32) int valid[kLanes];
  FilterContext fc;
  rtcInitIntersectContext(&fc.ctx);
  fc.ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  const bool counting = mode == TraceMode::bounds && any_closed;
  fc.ctx.filter = counting ? offer_hits : nullptr;

  const bool sun = light.kind() == LightKind::sun;
  const float t_min = sun ? 0.0f : float(light.near_plane());
  const float t_max = sun ? 1.0f : float(light.far_plane());

  bool active[kLanes];
  uint32_t n_lanes = 0;
  for (unsigned l = 0; l < kLanes; ++l) {
    const uint32_t i = px * kPacketW + l % kPacketW, j = py * kPacketH + l / kPacketW;
    active[l] = i < r.width && j < r.height;
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
  }
  if (n_lanes == 0) return;
  st.rays += n_lanes;
  st.texels += n_lanes;

  // First traversal: lo for everyone, and the first group of hits for counting.
  rtcIntersect8(valid, scene, &fc.ctx, &rh);
  st.traversals += n_lanes;
  uint32_t n_active = 0;
  for (unsigned l = 0; l < kLanes; ++l) {
    if (!active[l]) continue;
    active[l] = false;
    if (rh.hit.geomID[l] == RTC_INVALID_GEOMETRY_ID) continue;  // lit
    if (!counting) {
      fc.lane[l].take_first_hit(rh.ray.tfar[l]);
      continue;
    }
    active[l] = fc.lane[l].first_traversal_done();
    n_active += active[l];
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
    rtcIntersect8(valid, scene, &fc.ctx, &rh);
    st.traversals += n_active;
    for (unsigned l = 0; l < kLanes; ++l) {
      if (!active[l] || fc.lane[l].traversal_done()) continue;
      active[l] = false;
      --n_active;
    }
  }

  for (unsigned l = 0; l < kLanes; ++l) {
    const uint32_t i = px * kPacketW + l % kPacketW, j = py * kPacketH + l / kPacketW;
    if (i >= r.width || j >= r.height) continue;
    const ExitDepthRay& ray = fc.lane[l];
    const Interval iv = ray.interval(light);
    out.at(i, j) = iv;
    st.fallbacks += ray.fell_back();
    if (!ray.hit()) continue;
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
