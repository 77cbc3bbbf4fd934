// Dual depth bounds with Embree 3: see depth_bounds.hpp for the contract.
#include "tiles/bake/depth_bounds.hpp"

#include <embree3/rtcore.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <mutex>
#include <optional>
#include <string>
#include <type_traits>
#include <unordered_map>
#include <vector>

#include "common/error.hpp"
#include "tiles/bake/canonical_coverage.hpp"
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

// Embree passes our context pointer to the filter; RTCIntersectContext must come first.
// Each lane's counting state also holds what the filter gathers for it.
struct FilterContext {
  RTCIntersectContext ctx;
  ExitDepthRay lane[kMaxLanes];
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

// ---------------------------------------------------------------------------------------
// Canonical coverage with Embree as the candidate finder (canonical_coverage.hpp).
//
// Each triangle that can ever be hit (its canonical plane is not parallel to every texel
// ray) is an Embree user primitive whose box provably contains a point of every texel
// ray the definition covers (grown_box and slab_box below); the intersect callback runs the
// definition (canonical_cover, the canonical plane's t) and appends hits without
// accepting any, so one traversal of the whole line visits every candidate. The sorted,
// deduplicated hit list then goes through canonical_interval(): the same function of the
// same list as the rasterizer, hence the same bits.
//
// Why the boxes are a superset. For the exact ray (o, d) (the double values the
// definition takes) and a triangle P0 P1 P2, the three exact oriented edge values e_i
// (edge opposite P_i) add up to d . n with n = (P1 - P0) x (P2 - P0), and l_i = e_i / (d . n)
// are the barycentric coordinates of the point X where the ray meets the triangle's
// plane. The definition's double value of e_i is within B_i of the exact one (the same
// bound as the rasterizer's edge setup: 2^-47 of the magnitudes of its terms), so a
// covered ray (three equal signs s) has s e_i >= -B_i for each i, and a zero resolved by
// perturbation has |e_i| <= B_i too. Let k_i = B_i / |d . n| (sun: one d; spot: with
// |d|inf t = |X - o|inf and (d . n) t = h = (P0 - o) . n, k_i <= K_i |X - o|inf / |h|).
// When the k_i add up to at most 1/4: s = sign(d . n) (the opposite needs sum k >= 1/2),
// and l_i >= -2 k_i, so X lies in the triangle grown about each vertex
//   X_k = P_k + sum_{i != k} 2 k_i (P_k - P_i)   (k = 0, 1, 2),
// whose box therefore holds X, a point of the ray. Embree's float ray starts S parameter
// units before the texel origin (o - S d), far enough that every such X lies on the
// traversed segment [0, inf); the box is widened by 2^-18 of the coordinates involved,
// far more than the float rounding of the ray's origin and direction (2^-24), and the
// scene is built robust (conservative box tests). A triangle whose k_i add up to more
// than 1/4 (nearly edge-on, or a sliver below about 1e-7 of the scene): under a sun, the
// box of a slab around its plane that holds every covered ray (slab_box; a wall under an
// overhead sun); under a spot light, a box every texel ray crosses (the light position
// with the scene). The callback then rejects nothing the definition accepts: it is the
// definition.
//
// The ground frame (LightKind::sun_ground, a sheared map). Its texel rays share one
// direction d = g (far - near) (g = forward / (forward . n), n = axis_u x axis_v) and
// their origins o = origin + axis_u (u E) + axis_v (v E) + g near lie in one plane
// normal to n, not to d. Nothing above uses d . (o - o') = 0: the edge bounds B_i, the
// grown triangle and the slab need only the one direction d and a componentwise bound
// o_max on the origins (the map square's four corners; the origins are affine in the
// texel centre, so they lie in the hull of the corners, up to texel_ray's rounding,
// which is bounded with |g near| in place of |near|), and the light volume box holds the
// parallelepiped of the rays at t in [0, 1] (the corners and the corners + d). What
// changes is how far before a texel origin a box point can lie: the ray parameter of a
// point X on the ray through o is (X - o) . n / (d . n), the same for every origin of the
// plane, so S is measured along n (LightSpace::depth_axis) instead of the forward axis.
// With that, every covered ray still meets its triangle's box on the traversed segment,
// and the argument holds word for word.
//
// A windowed spot (LightKind::spot_window, an area light sample's sheared frame) is a
// spot for all of this: its texel rays still share one origin and have a unit forward
// component (|d|2 >= 1), and nothing above uses where on the image plane they point; only
// the bound |d|inf over the map (d_max, for the float ray error) takes the shift, through
// LightSpace::perspective_dir at the map's corners (d is affine in u, v).
namespace {

struct CoverageData {
  std::vector<Vec3d> v;                     // recentred vertices (double)
  std::vector<std::array<uint32_t, 3>> tri;  // scene triangles
  std::vector<uint32_t> prim_tri;           // user primitive -> scene triangle
  std::vector<CanonicalPlane> plane;        // by scene triangle
  std::vector<uint32_t> mesh;               // by scene triangle
  std::vector<uint8_t> closed;              // by scene triangle
  // Sun: the fast edge forms (a -> b, b -> c, c -> a) by scene triangle; empty for a spot.
  std::vector<std::array<CanonicalEdgeFast, 3>> fast;
  std::vector<RTCBounds> box;               // by user primitive
  uint64_t wide = 0;                        // primitives with the light-wide box (spot)
  uint64_t slab = 0;                        // primitives with a slab box (sun)
  double shift = 1;                         // S: parameter units before the texel origin
};

struct CoverageContext {
  RTCIntersectContext ctx;  // first: Embree hands our pointer back
  const CoverageData* data;
  double t_lo, t_hi;  // the accepted canonical t range
  CoverageRay ray[kMaxLanes];
  std::vector<CanonicalHit>* hits[kMaxLanes];
};
static_assert(std::is_standard_layout_v<CoverageContext>);

// The definition on one candidate for every valid lane; never accepts (traversal goes on).
void cover_candidate(const RTCIntersectFunctionNArguments* args) {
  const auto* cc = reinterpret_cast<const CoverageContext*>(args->context);
  const CoverageData& cd = *cc->data;
  if (args->primID >= cd.prim_tri.size()) return;
  const uint32_t t = cd.prim_tri[args->primID];
  const Vec3d& a = cd.v[cd.tri[t][0]];
  const Vec3d& b = cd.v[cd.tri[t][1]];
  const Vec3d& c = cd.v[cd.tri[t][2]];
  const std::array<CanonicalEdgeFast, 3>* fast = cd.fast.empty() ? nullptr : &cd.fast[t];
  RTCRayN* rays = RTCRayHitN_RayN(args->rayhit, args->N);
  for (unsigned i = 0; i < args->N; ++i) {
    if (args->valid[i] == 0) continue;
    const unsigned lane = RTCRayN_id(rays, args->N, i);
    if (lane >= kMaxLanes) continue;
    const CoverageRay& r = cc->ray[lane];
    int f;
    if (fast) {  // the rasterizer's shortcut: definite fast signs are the definition's
      const int s0 = (*fast)[0].sure_sign(r.o), s1 = (*fast)[1].sure_sign(r.o), s2 = (*fast)[2].sure_sign(r.o);
      if (s0 * s1 < 0 || s1 * s2 < 0 || s0 * s2 < 0) continue;
      f = s0 != 0 && s0 == s1 && s1 == s2 ? s0 : canonical_cover(r, a, b, c);
    } else {
      f = canonical_cover(r, a, b, c);
    }
    if (f == 0) continue;
    const double tp = cd.plane[t].t(r.o, r.d, NAN);
    if (!(tp >= cc->t_lo && tp <= cc->t_hi)) continue;  // also a non-finite t
    cc->hits[lane]->push_back(CanonicalHit{tp, t, cd.mesh[t], int8_t(f), cd.closed[t] != 0});
  }
}

// Per thread, the hit list of each lane of a packet (kept: no allocation per texel).
std::vector<CanonicalHit>* lane_hits() {
  thread_local std::vector<CanonicalHit> hits[kMaxLanes];
  return hits;
}

void coverage_bounds(const RTCBoundsFunctionArguments* args) {
  const auto* cd = static_cast<const CoverageData*>(args->geometryUserPtr);
  *args->bounds_o = cd->box[args->primID];
}

using canonical_detail::abs3;
using canonical_detail::cross_abs;
double max3(const Vec3d& v) { return std::max({v.x, v.y, v.z}); }
double sum3(const Vec3d& v) { return v.x + v.y + v.z; }

// The grown triangle's box (see above), or nullopt where the k_i add up to more than 1/4.
// Sun: `d` the rays' direction, `o_max` the componentwise bound of |texel origin| over
// the map. Spot: `d` unused, `o` the rays' common origin (o_max = |o|).
std::optional<Aabb> grown_box(const Vec3d (&p)[3], bool sun, const Vec3d& d, const Vec3d& o,
                              const Vec3d& o_max) {
  const Vec3d n = cross(p[1] - p[0], p[2] - p[0]);
  const Vec3d n_mag = cross_abs(abs3(p[1]) + abs3(p[0]), abs3(p[2]) + abs3(p[0]));
  double K[3];
  for (int i = 0; i < 3; ++i) {  // edge opposite p[i]
    const Vec3d P = abs3(p[(i + 1) % 3]) + o_max, Q = abs3(p[(i + 2) % 3]) + o_max;
    K[i] = 0x1p-47 * (sun ? dot(abs3(d), cross_abs(P, Q)) : sum3(cross_abs(P, Q))) + 0x1p-1000;
  }
  double denom, scale;  // k_i = K_i * scale / denom
  if (sun) {
    const double s = dot(d, n);
    denom = std::fabs(s) - (0x1p-47 * dot(abs3(d), n_mag) + 0x1p-1000);
    scale = 1;
  } else {
    const double h = dot(p[0] - o, n);
    denom = std::fabs(h) - (0x1p-47 * dot(abs3(p[0]) + o_max, n_mag) + 0x1p-1000);
    scale = 0;
    for (const Vec3d& q : p) scale = std::max(scale, max3(abs3(q - o)));
    scale *= 1 + 0x1p-40;
  }
  if (!(denom > 0)) return std::nullopt;
  double k[3], sum = 0;
  for (int i = 0; i < 3; ++i) sum += k[i] = K[i] * scale / denom * (1 + 0x1p-40);
  if (!(sum <= 0.25)) return std::nullopt;
  Aabb box;
  for (int j = 0; j < 3; ++j) {
    Vec3d x = p[j];
    for (int i = 0; i < 3; ++i)
      if (i != j) x = x + (p[j] - p[i]) * (2 * k[i]);
    box.extend(x);
  }
  if (!is_finite(box.lo) || !is_finite(box.hi)) return std::nullopt;
  return box;
}

double comp(const Vec3d& v, int k) { return k == 0 ? v.x : (k == 1 ? v.y : v.z); }

// Sun, a triangle the grown box cannot confine (nearly edge-on to the sun, or a sliver):
// a covered ray has s e_i >= -B_i for each edge and the e_i add up to D = d . n, so
// |e_i| <= C = |D| + sum B_i. On the exact ray through any of its points P, e_i is the
// affine a . P + b with a = d x (q1 - q0), b = d . (q0 x q1) (edge q0 -> q1), the same
// for every point of the line: the ray lies in the slab |a . P + b| <= C of one edge (the
// one with the largest a), and its points at t in [0, 1] in `vol`, the box of the light
// volume. Returns the box of that slab within `vol` (per axis, the range the slab allows
// over the box's other two axes), nullopt where the slab misses `vol` (never covered).
// C carries the rounding of a, b and of these ranges, generously.
std::optional<Aabb> slab_box(const Vec3d (&p)[3], const Vec3d& d, const Aabb& vol) {
  const Vec3d P_max{std::max(std::fabs(vol.lo.x), std::fabs(vol.hi.x)),
                    std::max(std::fabs(vol.lo.y), std::fabs(vol.hi.y)),
                    std::max(std::fabs(vol.lo.z), std::fabs(vol.hi.z))};
  const Vec3d n = cross(p[1] - p[0], p[2] - p[0]);
  double C = std::fabs(dot(d, n)) +
             0x1p-47 * dot(abs3(d), cross_abs(abs3(p[1]) + abs3(p[0]), abs3(p[2]) + abs3(p[0])));
  int best = 0;
  double best_len = -1;
  for (int i = 0; i < 3; ++i) {
    const Vec3d& q0 = p[(i + 1) % 3];
    const Vec3d& q1 = p[(i + 2) % 3];
    // B_i for any origin in `vol` (which holds every texel origin).
    C += 0x1p-47 * dot(abs3(d), cross_abs(abs3(q0) + P_max, abs3(q1) + P_max));
    const double len = sum3(abs3(cross(d, q1 - q0)));
    if (len > best_len) best_len = len, best = i;
  }
  const Vec3d& q0 = p[(best + 1) % 3];
  const Vec3d& q1 = p[(best + 2) % 3];
  const Vec3d a = cross(d, q1 - q0);
  const double b = dot(d, cross(q0, q1));
  // The rounding of a and b against the exact affine function over `vol`.
  C += 0x1p-45 * (dot(abs3(d), cross_abs(abs3(q0), abs3(q1))) +
                  dot(P_max, cross_abs(abs3(d), abs3(q0) + abs3(q1))));
  C *= 1 + 0x1p-30;
  if (!std::isfinite(C) || !is_finite(a) || !std::isfinite(b)) return Aabb{vol};
  const double slack = 0x1p-40 * (dot(abs3(a), P_max) + std::fabs(b) + C) + 0x1p-1000;
  Aabb out;
  double lo_o[3], hi_o[3];
  for (int k = 0; k < 3; ++k) {
    double m = 0, M = 0;
    for (int j = 0; j < 3; ++j) {
      if (j == k) continue;
      const double x0 = comp(a, j) * comp(vol.lo, j), x1 = comp(a, j) * comp(vol.hi, j);
      m += std::min(x0, x1), M += std::max(x0, x1);
    }
    const double ak = comp(a, k);
    double lo = comp(vol.lo, k), hi = comp(vol.hi, k);
    if (ak == 0) {
      if (m > C - b + slack || M < -C - b - slack) return std::nullopt;
    } else {
      const double x1 = (C - b - m + slack) / ak, x2 = (-C - b - M - slack) / ak;
      double upper = ak > 0 ? x1 : x2, lower = ak > 0 ? x2 : x1;
      upper += std::fabs(upper) * 0x1p-40 + 0x1p-1000;
      lower -= std::fabs(lower) * 0x1p-40 + 0x1p-1000;
      if (std::isfinite(upper)) hi = std::min(hi, upper);
      if (std::isfinite(lower)) lo = std::max(lo, lower);
      if (!(lo <= hi)) return std::nullopt;
    }
    lo_o[k] = lo, hi_o[k] = hi;
  }
  out.lo = {lo_o[0], lo_o[1], lo_o[2]};
  out.hi = {hi_o[0], hi_o[1], hi_o[2]};
  return out;
}

// Outward rounding to float.
RTCBounds to_bounds(const Aabb& b) {
  auto down = [](double x) {
    float f = float(x);
    return double(f) > x ? std::nextafter(f, -INFINITY) : f;
  };
  auto up = [](double x) {
    float f = float(x);
    return double(f) < x ? std::nextafter(f, INFINITY) : f;
  };
  RTCBounds r;
  r.lower_x = down(b.lo.x), r.lower_y = down(b.lo.y), r.lower_z = down(b.lo.z);
  r.upper_x = up(b.hi.x), r.upper_y = up(b.hi.y), r.upper_z = up(b.hi.z);
  return r;
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
  RTCScene cover_scene = nullptr;  // canonical coverage: user primitives (bounds modes)
  CoverageData cover;
  // The float triangle scene of the baseline modes (first_hit, bounds_tracer_t), built on
  // first use: no memory or build time for the canonical modes.
  std::once_flag triangles_once;
  RTCScene scene = nullptr;
  ClosedFaces closed_faces;  // by primitive id of the closed geometry; planes relative to centre
  uint64_t triangles = 0;
  bool any_closed = false;
  double build_s = 0;

  ~Impl() {
    if (scene) rtcReleaseScene(scene);
    if (cover_scene) rtcReleaseScene(cover_scene);
    if (device) rtcReleaseDevice(device);
  }

  void build(const Scene& s);
  void build_coverage(const Scene& s, const std::vector<uint8_t>& is_closed,
                      const std::vector<uint32_t>& tri_mesh);
  void build_triangles();
  void mark_touchable(double scene_size);
  template <class RayHit, unsigned W, unsigned H>
  void trace_packet(const TraceRegion& r, uint32_t px, uint32_t py, TraceMode mode,
                    IntervalTile& out, DepthBoundsStats& st) const;
  template <class RayHit, unsigned W, unsigned H>
  void trace_packet_canonical(const TraceRegion& r, uint32_t px, uint32_t py, TraceMode mode,
                              IntervalTile& out, DepthBoundsStats& st) const;
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
  any_closed = std::find(is_closed.begin(), is_closed.end(), 1) != is_closed.end();

  device = rtcNewDevice(nullptr);
  if (!device) throw Error("embree: cannot create a device: " + embree_error(nullptr));
  build_coverage(s, is_closed, tri_mesh);
  build_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
}

// The baseline modes' scene: Embree's float triangles, closed and open in two geometries
// (MH §3.1: open geometry gives hi = lo), from the coverage data's recentred vertices.
void DepthBoundsTracer::Impl::build_triangles() {
  const CoverageData& cd = cover;
  const size_t nv = cd.v.size(), nt = cd.tri.size();
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
    const Vec3d& p = cd.v[i];
    vp[3 * i] = float(p.x), vp[3 * i + 1] = float(p.y), vp[3 * i + 2] = float(p.z);
  }
  vp[3 * nv] = 0;

  for (unsigned geom_id : {kClosedGeom, kOpenGeom}) {
    const bool closed = geom_id == kClosedGeom;
    size_t count = 0;
    for (size_t i = 0; i < nt; ++i) count += (cd.closed[i] != 0) == closed;
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
      if ((cd.closed[i] != 0) != closed) continue;
      const auto& t = cd.tri[i];
      ip[3 * k] = t[0], ip[3 * k + 1] = t[1], ip[3 * k + 2] = t[2];
      if (closed) {
        const Vec3d& a = cd.v[t[0]];
        const Vec3d normal = cross(cd.v[t[1]] - a, cd.v[t[2]] - a);
        Facing facing = Facing::per_ray;
        if (light.parallel()) {  // one direction for every texel ray
          const double f = dot(normal, light.forward());
          facing = f < 0 ? Facing::front : (f > 0 ? Facing::back : Facing::edge_on);
        }
        closed_faces.add(cd.mesh[i], facing, normal, dot(normal, a));
      }
      ++k;
    }
    rtcCommitGeometry(g);
    rtcAttachGeometryByID(scene, g, geom_id);
    rtcReleaseGeometry(g);
  }
  rtcReleaseBuffer(vbuf);
  Aabb b;
  for (const Vec3d& p : cd.v) b.extend(p);
  mark_touchable(b.empty() ? 1.0 : std::max({b.extent().x, b.extent().y, b.extent().z, 1e-300}));
  rtcCommitScene(scene);
  if (rtcGetDeviceError(device) != RTC_ERROR_NONE)
    throw Error("embree: building the triangle scene failed: " + embree_error(device));
}

void DepthBoundsTracer::Impl::build_coverage(const Scene& s, const std::vector<uint8_t>& is_closed,
                                             const std::vector<uint32_t>& tri_mesh) {
  CoverageData& cd = cover;
  const size_t nv = s.vertices.size(), nt = s.triangles.size();
  cd.v.resize(nv);
  for (size_t i = 0; i < nv; ++i) cd.v[i] = s.vertices[i] - centre;
  cd.tri = s.triangles;
  cd.mesh = tri_mesh;
  cd.closed = is_closed;
  cd.plane.resize(nt);
  const bool sun = light.parallel();
  const double E = light.extent_uv();
  // The texel rays' extremes: every texel centre lies inside the map square (u, v in
  // [0, 1]), origins and directions are affine in it.
  Vec3d corner[4], o_max{0, 0, 0};
  double d_max = 0;  // bound on |d|inf over the texel rays
  for (int c = 0; c < 4; ++c) {
    const double u = c & 1, v = c >> 1;
    if (sun) {
      corner[c] = light.origin() + light.axis_u() * (u * E) + light.axis_v() * (v * E) +
                  light.ray_axis() * light.near_plane() - centre;
      d_max = max3(abs3(light.texel_ray(0, 0, 0).dir));
    } else {
      corner[c] = light.origin() - centre;
      d_max = std::max(d_max, max3(abs3(light.perspective_dir(u, v))));  // a window's shift included
    }
    const Vec3d a = abs3(corner[c]);
    o_max = {std::max(o_max.x, a.x), std::max(o_max.y, a.y), std::max(o_max.z, a.z)};
  }
  {  // the rounding of texel_ray and of the recentring, generously
    const double g = max3(abs3(light.origin())) + max3(abs3(centre)) + max3(o_max) + E * 4 +
                     std::max(std::fabs(light.near_plane()), max3(abs3(light.ray_axis() * light.near_plane())));
    o_max = o_max * (1 + 0x1p-30) + Vec3d{1, 1, 1} * (g * 0x1p-40 + 0x1p-1000);
  }
  d_max *= 1 + 0x1p-30;
  const Vec3d d_sun = light.texel_ray(0, 0, 0).dir;
  const Vec3d o_spot = light.origin() - centre;
  // A box every texel ray crosses: sun, the near-plane map square (the origins); spot,
  // the light position (the origin) with the scene.
  Aabb wide, volume;  // volume: the box of the sun's light volume (t in [0, 1])
  for (const Vec3d& c : corner) wide.extend(c), volume.extend(c), volume.extend(c + d_sun);
  if (!sun)
    for (const Vec3d& q : cd.v) wide.extend(q);
  volume.lo = volume.lo - abs3(volume.lo) * 0x1p-30 - o_max * 0x1p-30;
  volume.hi = volume.hi + abs3(volume.hi) * 0x1p-30 + o_max * 0x1p-30;

  if (sun) cd.fast.resize(nt);
  std::vector<Aabb> boxes(nt);
  std::vector<uint8_t> kind(nt, 0);  // 0: never hit, 1: grown box, 2: wide, 3: slab box
  tbb::parallel_for(size_t(0), nt, [&](size_t t) {
    const Vec3d p[3] = {cd.v[cd.tri[t][0]], cd.v[cd.tri[t][1]], cd.v[cd.tri[t][2]]};
    cd.plane[t] = CanonicalPlane::of(p[0], p[1], p[2]);
    const Vec3d& n = cd.plane[t].n;
    if (sun)
      cd.fast[t] = {CanonicalEdgeFast::of(p[0], p[1], d_sun, o_max), CanonicalEdgeFast::of(p[1], p[2], d_sun, o_max),
                    CanonicalEdgeFast::of(p[2], p[0], d_sun, o_max)};
    if (n.x == 0 && n.y == 0 && n.z == 0) return;      // every ray in the plane: no t
    if (sun && dot(n, d_sun) == 0) return;             // the sun's rays lie in the plane
    if (auto b = grown_box(p, sun, d_sun, o_spot, o_max)) {
      boxes[t] = *b;
      kind[t] = 1;
    } else if (!sun) {
      kind[t] = 2;
    } else if (auto sb = slab_box(p, d_sun, volume)) {
      boxes[t] = *sb;  // crossed by its rays within the light volume (t in [0, 1])
      kind[t] = 3;
    }
  });
  // S: every point of a grown box lies at ray parameter >= -S + 1 (sun: depth along the
  // light's depth axis, forward or the ground frame's n: the texel origins' plane normal; spot: |t| <= |X - o|2 / |d|2 with |d|2 >= 1).
  double shift = 1;
  for (size_t t = 0; t < nt; ++t) {
    if (kind[t] != 1) continue;
    for (int c = 0; c < 8; ++c) {
      const Vec3d x{c & 1 ? boxes[t].hi.x : boxes[t].lo.x, c & 2 ? boxes[t].hi.y : boxes[t].lo.y,
                    c & 4 ? boxes[t].hi.z : boxes[t].lo.z};
      if (sun) {
        const double tx = dot(x - corner[0], light.depth_axis()) / dot(d_sun, light.depth_axis());
        shift = std::max(shift, 1 - tx);
      } else {
        shift = std::max(shift, 1 + 2 * length(x - o_spot));
      }
    }
  }
  cd.shift = shift = shift * (1 + 0x1p-20);
  // Float ray error at a point X: 2^-24 (2 |o - S d|inf + |X|inf); 2^-18 is 32 times that.
  const double o_far = max3(o_max) + shift * d_max;
  auto widen = [&](const Aabb& b) {
    const double m = 0x1p-18 * (2 * o_far + std::max(max3(abs3(b.lo)), max3(abs3(b.hi))));
    Aabb w = b;
    w.lo = w.lo - Vec3d{m, m, m};
    w.hi = w.hi + Vec3d{m, m, m};
    return to_bounds(w);
  };
  const RTCBounds wide_bounds = widen(wide);
  for (size_t t = 0; t < nt; ++t) {
    if (kind[t] == 0) continue;
    cd.prim_tri.push_back(uint32_t(t));
    cd.box.push_back(kind[t] == 2 ? wide_bounds : widen(boxes[t]));
    cd.wide += kind[t] == 2;
    cd.slab += kind[t] == 3;
  }

  cover_scene = rtcNewScene(device);
  rtcSetSceneFlags(cover_scene, RTC_SCENE_FLAG_ROBUST);
  rtcSetSceneBuildQuality(cover_scene, RTC_BUILD_QUALITY_MEDIUM);
  if (!cd.prim_tri.empty()) {
    RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_USER);
    rtcSetGeometryUserPrimitiveCount(g, unsigned(cd.prim_tri.size()));
    rtcSetGeometryUserData(g, &cd);
    rtcSetGeometryBoundsFunction(g, coverage_bounds, &cd);
    rtcSetGeometryIntersectFunction(g, cover_candidate);
    rtcCommitGeometry(g);
    rtcAttachGeometry(cover_scene, g);
    rtcReleaseGeometry(g);
  }
  rtcCommitScene(cover_scene);
  if (rtcGetDeviceError(device) != RTC_ERROR_NONE)
    throw Error("embree: building the coverage scene of '" + s.name + "' failed: " + embree_error(device));
}

template <class RayHit, unsigned W, unsigned H>
void DepthBoundsTracer::Impl::trace_packet_canonical(const TraceRegion& r, uint32_t px, uint32_t py,
                                                     TraceMode mode, IntervalTile& out,
                                                     DepthBoundsStats& st) const {
  constexpr unsigned kLanes = W * H;
  static_assert(kLanes <= kMaxLanes);
  alignas(64) RayHit rh;
  alignas(64) int valid[kLanes];
  CoverageContext cc;
  rtcInitIntersectContext(&cc.ctx);
  cc.ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  cc.data = &cover;
  const bool sun = light.parallel();
  cc.t_lo = sun ? 0.0 : light.near_plane();
  cc.t_hi = sun ? 1.0 : light.far_plane();
  std::vector<CanonicalHit>* hits = lane_hits();
  bool used[kLanes];
  uint32_t n_lanes = 0;
  for (unsigned l = 0; l < kLanes; ++l) {
    const uint32_t i = px * W + l % W, j = py * H + l / W;
    used[l] = i < r.width && j < r.height;
    valid[l] = used[l] ? -1 : 0;
    rh.ray.tnear[l] = 0;
    rh.ray.tfar[l] = INFINITY;
    rh.ray.mask[l] = 0xFFFFFFFFu;
    rh.ray.id[l] = l;
    rh.ray.flags[l] = 0;
    rh.ray.time[l] = 0;
    rh.hit.geomID[l] = RTC_INVALID_GEOMETRY_ID;
    hits[l].clear();
    cc.hits[l] = &hits[l];
    if (!used[l]) {
      rh.ray.org_x[l] = rh.ray.org_y[l] = rh.ray.org_z[l] = 0;
      rh.ray.dir_x[l] = rh.ray.dir_y[l] = 0, rh.ray.dir_z[l] = 1;
      continue;
    }
    ++n_lanes;
    const LightRay ray = light.texel_ray(r.level, r.x0 + i, r.y0 + j);
    const Vec3d o = ray.origin - centre;
    cc.ray[l] = CoverageRay::of(o, ray.dir);
    const Vec3d start = o - ray.dir * cover.shift;
    rh.ray.org_x[l] = float(start.x), rh.ray.org_y[l] = float(start.y), rh.ray.org_z[l] = float(start.z);
    rh.ray.dir_x[l] = float(ray.dir.x), rh.ray.dir_y[l] = float(ray.dir.y);
    rh.ray.dir_z[l] = float(ray.dir.z);
  }
  if (n_lanes == 0) return;
  st.rays += n_lanes;
  st.texels += n_lanes;
  intersect(valid, cover_scene, &cc.ctx, &rh);
  st.traversals += n_lanes;

  const double range = cc.t_hi - cc.t_lo;
  for (unsigned l = 0; l < kLanes; ++l) {
    if (!used[l]) continue;
    std::vector<CanonicalHit>& h = hits[l];
    std::sort(h.begin(), h.end());
    // A primitive referenced from two leaves is reported twice: equal (t, tri), adjacent.
    h.erase(std::unique(h.begin(), h.end(),
                        [](const CanonicalHit& x, const CanonicalHit& y) { return x.t == y.t && x.tri == y.tri; }),
            h.end());
    const CanonicalResult res = canonical_interval(h, range);
    Interval iv = canonical_depths(light, res);
    if (mode == TraceMode::static_bounds && !h.empty() && !res.fell_back && iv.hi == iv.lo) {
      // The static-geometry interval: up to just below the next surface along the ray.
      float next = INFINITY;
      for (const CanonicalHit& x : h) {
        const float dpt = canonical_depth(light, x.t);
        if (dpt > iv.lo) {
          next = dpt;
          break;
        }
      }
      iv.hi = next == INFINITY ? kLitDepth : std::max(iv.lo, std::nextafter(next, -INFINITY));
    }
    const uint32_t i = px * W + l % W, j = py * H + l / W;
    out.at(i, j) = iv;
    st.fallbacks += res.fell_back;
    if (h.empty()) continue;
    ++st.hits;
    if (iv.hi > iv.lo) ++st.closed;
  }
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
  const bool counting = mode != TraceMode::first_hit && any_closed;
  fc.ctx.filter = counting ? offer_hits : nullptr;

  const bool sun = light.parallel();
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
  }
  if (n_lanes == 0) return;
  st.rays += n_lanes;
  st.texels += n_lanes;

  // First traversal: the first hit for everyone, and the first group of hits for counting.
  intersect(valid, scene, &fc.ctx, &rh);
  st.traversals += n_lanes;
  uint32_t n_active = 0;
  for (unsigned l = 0; l < kLanes; ++l) {
    if (!active[l]) continue;
    active[l] = false;
    valid[l] = 0;
    if (rh.hit.geomID[l] == RTC_INVALID_GEOMETRY_ID) continue;  // lit
    if (!counting) fc.lane[l].take_first_hit(rh.ray.tfar[l]);
    else active[l] = fc.lane[l].first_traversal_done();
    n_active += active[l];
    valid[l] = -1;
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
  }

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

template <class RayHit, unsigned W, unsigned H>
void DepthBoundsTracer::Impl::trace_rows(const TraceRegion& r, TraceMode mode, IntervalTile& tile,
                                         std::atomic<uint64_t>* progress,
                                         DepthBoundsStats& total) const {
  const uint32_t rows = (r.height + H - 1) / H;
  const uint32_t cols = (r.width + W - 1) / W;
  std::atomic<uint64_t> rays{0}, traversals{0}, hits{0}, closed{0}, fallbacks{0}, texels{0};
  const bool canonical = mode == TraceMode::bounds || mode == TraceMode::static_bounds;
  tbb::parallel_for(tbb::blocked_range<uint32_t>(0, rows), [&](const tbb::blocked_range<uint32_t>& br) {
    DepthBoundsStats local;
    for (uint32_t py = br.begin(); py != br.end(); ++py) {
      const uint64_t before = local.texels;
      for (uint32_t px = 0; px < cols; ++px) {
        if (canonical) trace_packet_canonical<RayHit, W, H>(r, px, py, mode, tile, local);
        else trace_packet<RayHit, W, H>(r, px, py, mode, tile, local);
      }
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
uint64_t DepthBoundsTracer::wide_candidates() const { return impl_->cover.wide + impl_->cover.slab; }

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
  if (mode == TraceMode::first_hit || mode == TraceMode::bounds_tracer_t)
    std::call_once(impl_->triangles_once, [&] { impl_->build_triangles(); });
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
