#include "render/render.hpp"

#include "tiles/core/filter_level.hpp"

#include <embree3/rtcore.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cassert>
#include <cmath>
#include <limits>

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>  // SSE2 and, in functions built for it, AVX (sun_tap_queries)
#elif defined(__SSE2__)
#include <emmintrin.h>
#endif

#include <Iex.h>
#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfOutputFile.h>

#include <algorithm>
#include <chrono>
#include <ctime>
#include <cmath>
#include <filesystem>
#include <limits>

#include "tiles/bake/deep_sampler.hpp"
#include "image/png_io.hpp"
#include "common/error.hpp"

namespace st {

struct SceneTracer::Impl {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  Vec3d centre;                       // vertices are recentred (float precision far from 0)
  std::vector<uint8_t> closed;        // per scene triangle
  std::vector<Vec3d> normals;         // per scene triangle, outward for closed meshes
  double scale = 1;                   // scene size, for ray offsets
  // Geometry kOpaqueGeom holds the opaque meshes, kPartialGeom the partial ones (when
  // any): each Embree primitive's scene triangle.
  std::vector<uint32_t> prim_triangle[2];
  // Alpha test of primary rays on partial meshes (per scene triangle: its texture or -1).
  std::vector<int32_t> triangle_alpha;
  std::vector<std::array<Vec2f, 3>> uv;
  std::vector<AlphaTexture> textures;
  // The partial occluders' transmittance along light rays (null without any).
  std::unique_ptr<DeepSampler> deep;
  ~Impl() {
    if (scene) rtcReleaseScene(scene);
    if (device) rtcReleaseDevice(device);
  }
};

namespace {

constexpr unsigned kOpaqueGeom = 0, kPartialGeom = 1;

// Primary rays on a partial mesh: an alpha-tested triangle is hit only where its texture
// is solid (as the deep sampler's crossings), so cut-away card corners are not receivers.
void partial_intersect_filter(const RTCFilterFunctionNArguments* args) {
  const auto* impl = static_cast<const SceneTracer::Impl*>(args->geometryUserPtr);
  for (unsigned i = 0; i < args->N; ++i) {
    if (args->valid[i] == 0) continue;
    const uint32_t tri = impl->prim_triangle[kPartialGeom][RTCHitN_primID(args->hit, args->N, i)];
    const int32_t a = impl->triangle_alpha[tri];
    if (a < 0) continue;
    const float bu = RTCHitN_u(args->hit, args->N, i), bv = RTCHitN_v(args->hit, args->N, i);
    const auto& c = impl->uv[tri];
    const float w0 = 1 - bu - bv;
    const float tu = w0 * c[0].u + bu * c[1].u + bv * c[2].u;
    const float tv = w0 * c[0].v + bu * c[1].v + bv * c[2].v;
    if (!impl->textures[size_t(a)].solid(tu, tv)) args->valid[i] = 0;
  }
}

// Shadow rays (rtcOccluded1) see only the opaque meshes: partial ones are the deep
// sampler's (transmittance()), as the opaque map leaves them to deep tiles.
void partial_occluded_filter(const RTCFilterFunctionNArguments* args) {
  for (unsigned i = 0; i < args->N; ++i) args->valid[i] = 0;
}

}  // namespace

SceneTracer::SceneTracer(const Scene& scene, const LightSpace& light) : impl_(std::make_unique<Impl>()), light_(light) {
  if (scene.triangles.empty()) throw Error("render: scene '" + scene.name + "' has no triangles");
  const Aabb b = scene.bounds();
  Impl& m = *impl_;
  m.centre = b.center();
  m.scale = std::max({b.extent().x, b.extent().y, b.extent().z, 1e-9});
  const size_t nt = scene.triangles.size();
  m.closed.assign(nt, 0);
  m.normals.resize(nt);
  m.triangle_alpha.assign(nt, -1);
  std::vector<uint8_t> partial(nt, 0);
  bool any_alpha = false;
  for (const Mesh& mesh : scene.meshes) {
    if (uint64_t(mesh.first_triangle) + mesh.triangle_count > nt)
      throw Error("render: scene '" + scene.name + "' mesh '" + mesh.name + "' references triangles past the end");
    for (uint32_t i = 0; i < mesh.triangle_count; ++i) {
      const uint32_t t = mesh.first_triangle + i;
      m.closed[t] = mesh.closed;
      partial[t] = mesh.partial();
      if (mesh.alpha_texture >= 0) {
        if (size_t(mesh.alpha_texture) >= scene.alpha_textures.size())
          throw Error("render: scene '" + scene.name + "' mesh '" + mesh.name + "' names a missing alpha texture");
        m.triangle_alpha[t] = mesh.alpha_texture;
        any_alpha = true;
      }
    }
  }
  if (any_alpha) {
    if (scene.triangle_uv.size() != nt)
      throw Error("render: scene '" + scene.name + "' has alpha-tested meshes but no UV per triangle");
    m.uv = scene.triangle_uv;
    m.textures = scene.alpha_textures;
  }
  for (size_t t = 0; t < nt; ++t) {
    const auto& tri = scene.triangles[t];
    for (int k = 0; k < 3; ++k)
      if (tri[k] >= scene.vertices.size())
        throw Error("render: scene '" + scene.name + "' triangle " + std::to_string(t) + " has a bad index");
    const Vec3d n = cross(scene.vertices[tri[1]] - scene.vertices[tri[0]], scene.vertices[tri[2]] - scene.vertices[tri[0]]);
    const double len = length(n);
    m.normals[t] = len > 0 ? n / len : Vec3d{0, 1, 0};
    m.prim_triangle[partial[t] ? kPartialGeom : kOpaqueGeom].push_back(uint32_t(t));
  }
  m.device = rtcNewDevice(nullptr);
  if (!m.device) throw Error("render: Embree device creation failed");
  m.scene = rtcNewScene(m.device);
  rtcSetSceneFlags(m.scene, RTC_SCENE_FLAG_ROBUST);
  for (unsigned geom : {kOpaqueGeom, kPartialGeom}) {
    const auto& prims = m.prim_triangle[geom];
    if (prims.empty()) continue;
    RTCGeometry g = rtcNewGeometry(m.device, RTC_GEOMETRY_TYPE_TRIANGLE);
    auto* vp = static_cast<float*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                           3 * sizeof(float), scene.vertices.size()));
    auto* ip = static_cast<unsigned*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                              3 * sizeof(unsigned), prims.size()));
    if (!vp || !ip) {
      rtcReleaseGeometry(g);
      throw Error("render: Embree cannot allocate the geometry buffers");
    }
    for (size_t i = 0; i < scene.vertices.size(); ++i) {
      const Vec3d v = scene.vertices[i] - m.centre;
      vp[3 * i] = float(v.x), vp[3 * i + 1] = float(v.y), vp[3 * i + 2] = float(v.z);
    }
    for (size_t p = 0; p < prims.size(); ++p)
      for (int k = 0; k < 3; ++k) ip[3 * p + k] = scene.triangles[prims[p]][k];
    if (geom == kPartialGeom) {
      rtcSetGeometryUserData(g, impl_.get());
      rtcSetGeometryIntersectFilterFunction(g, partial_intersect_filter);
      rtcSetGeometryOccludedFilterFunction(g, partial_occluded_filter);
    }
    rtcCommitGeometry(g);
    rtcAttachGeometryByID(m.scene, g, geom);
    rtcReleaseGeometry(g);
  }
  rtcCommitScene(m.scene);
  if (rtcGetDeviceError(m.device) != RTC_ERROR_NONE) throw Error("render: Embree scene build failed");
  if (scene.any_partial()) m.deep = std::make_unique<DeepSampler>(scene, light);
}

bool SceneTracer::has_partial() const { return impl_->deep != nullptr; }

SceneTracer::~SceneTracer() = default;

Vec3d SceneTracer::to_light(const Vec3d& p) const {
  if (light_.parallel()) return -light_.forward();
  return normalize(light_.origin() - p);
}

std::vector<Receiver> SceneTracer::primary(const Camera& camera, uint32_t width, uint32_t height) const {
  if (width == 0 || height == 0 || uint64_t(width) * height > (uint64_t(1) << 26))
    throw Error("render: image size must be 1..67M pixels");
  Camera cam = camera;
  cam.aspect = double(width) / double(height);
  const CameraBasis b = basis(cam);
  std::vector<Receiver> out(size_t(width) * height);
  const Vec3d o = cam.pos - impl_->centre;
  tbb::parallel_for(tbb::blocked_range<uint32_t>(0, height), [&](const tbb::blocked_range<uint32_t>& rows) {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    for (uint32_t y = rows.begin(); y < rows.end(); ++y)
      for (uint32_t x = 0; x < width; ++x) {
        const Vec3d d = ray_dir(b, (x + 0.5) / width, (y + 0.5) / height);
        RTCRayHit rh{};
        rh.ray.org_x = float(o.x), rh.ray.org_y = float(o.y), rh.ray.org_z = float(o.z);
        rh.ray.dir_x = float(d.x), rh.ray.dir_y = float(d.y), rh.ray.dir_z = float(d.z);
        rh.ray.tnear = 0;
        rh.ray.tfar = std::numeric_limits<float>::infinity();
        rh.ray.mask = ~0u;
        rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        rtcIntersect1(impl_->scene, &ctx, &rh);
        Receiver& r = out[size_t(y) * width + x];
        if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) continue;
        r.hit = true;
        r.distance = rh.ray.tfar;
        r.pos = cam.pos + d * double(rh.ray.tfar);
        const uint32_t tri = impl_->prim_triangle[rh.hit.geomID][rh.hit.primID];
        r.closed = impl_->closed[tri] != 0;
        r.normal = impl_->normals[tri];
        if (!r.closed && dot(r.normal, d) > 0) r.normal = -r.normal;  // open: face the camera
        r.n_dot_l = dot(r.normal, to_light(r.pos));
      }
  });
  return out;
}

namespace {
// 1 when the shadow ray from `org` (recentred) along `dir` reaches the light (a sun: no
// end; a spot: just short of its origin, seen from the receiver at `p`), else 0.
float lit_along(RTCScene scene, const Vec3d& org, const Vec3d& dir, const LightSpace& light, const Vec3d& p) {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRay ray{};
  ray.org_x = float(org.x), ray.org_y = float(org.y), ray.org_z = float(org.z);
  ray.dir_x = float(dir.x), ray.dir_y = float(dir.y), ray.dir_z = float(dir.z);
  ray.tnear = 0;
  ray.tfar = light.parallel() ? std::numeric_limits<float>::infinity()
                                             : float(length(light.origin() - p) * (1 - 1e-6));
  ray.mask = ~0u;
  rtcOccluded1(scene, &ctx, &ray);
  return ray.tfar == -std::numeric_limits<float>::infinity() ? 0.0f : 1.0f;
}
}  // namespace

float SceneTracer::traced(const Receiver& r, const Vec3d& offset) const {
  if (!r.hit || r.n_dot_l <= 0) return 0;
  const Vec3d p = r.pos + offset;
  const Vec3d dir = to_light(p);
  const Vec3d org = p - impl_->centre + r.normal * (1e-5 * impl_->scale);
  return lit_along(impl_->scene, org, dir, light_, p);
}

std::array<float, 3> SceneTracer::transmittance(const Receiver& r, const Vec3d& offset) const {
  if (!impl_->deep || !r.hit) return {1, 1, 1};
  // The light ray through the receiver's point (the shadow ray's line), moved off its
  // surface as traced() moves the shadow ray's start: the receiver's own crossing lies
  // behind it.
  const Vec3d p = r.pos + offset + r.normal * (1e-5 * impl_->scale);
  const LightPoint lp = light_.to_light(p);
  return impl_->deep->ray_function(lp.u, lp.v).eval(float(lp.d));
}

namespace {
Vec3d toward(const LightSpace& light, const Vec3d& p) {
  return light.parallel() ? -light.forward() : normalize(light.origin() - p);
}
}  // namespace

bool faces(const Receiver& r, const LightSpace& light) { return r.hit && dot(r.normal, toward(light, r.pos)) > 0; }

float SceneTracer::traced_toward(const Receiver& r, const LightSpace& light) const {
  if (!r.hit || r.n_dot_l <= 0) return 0;
  const Vec3d dir = toward(light, r.pos);
  if (dot(r.normal, dir) <= 0) return 0;  // facing away from this sample
  const Vec3d org = r.pos - impl_->centre + r.normal * (1e-5 * impl_->scale);
  return lit_along(impl_->scene, org, dir, light, r.pos);
}

namespace {
double process_cpu_seconds() {
  timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}
}  // namespace

LightPoint lookup_point(const Receiver& r, const LightSpace& light, uint32_t map_level, uint32_t pcf_radius) {
  Vec3d p = r.pos;
  {
    // Open geometry has hi = lo; closed surfaces meet stored lo values: move the lookup
    // off the surface (render.hpp).
    const double texel = light.texel_size(p, map_level);
    p = p + r.normal * ((r.closed ? kClosedReceiverOffsetTexels : kOpenReceiverOffsetTexels) + pcf_radius) * texel;
  }
  return light.to_light(p);
}

LightPoint deep_lookup_point(const Receiver& r, const LightSpace& light, uint32_t map_level, uint32_t deep_level,
                             uint32_t pcf_radius) {
  (void)map_level, (void)pcf_radius;  // no normal offset: it would shift (u, v) (render.hpp)
  const Vec3d toward = light.parallel() ? -light.forward() : normalize(light.origin() - r.pos);
  const double deep_texel = (light.parallel() ? light.extent_uv() : length(r.pos - light.origin()) * light.extent_uv()) /
                            double(uint64_t(1) << deep_level);
  return light.to_light(r.pos + toward * (kDeepDepthBiasTexels * deep_texel));
}

float receiver_footprint_world(const Receiver& r, double pixel_angle) { return float(r.distance * pixel_angle); }

float receiver_footprint_texels(const Receiver& r, const LightSpace& light, uint32_t map_level, double pixel_angle) {
  const double texel = light.texel_size(r.pos, map_level);
  return float(double(receiver_footprint_world(r, pixel_angle)) / texel);
}

float map_visibility(const Evaluator& eval, const Receiver& r, const LightSpace& light, uint32_t pcf_radius,
                     uint32_t level) {
  if (!r.hit || r.n_dot_l <= 0) return 0;
  const uint32_t L = eval.finest_level();
  const LightPoint lp = lookup_point(r, light, L, pcf_radius);
  if (!(lp.u >= 0 && lp.u < 1 && lp.v >= 0 && lp.v < 1)) return 1;
  const float d = float(lp.d);
  const uint32_t lv = std::min(level, L);
  const auto [x, y] = LightSpace::texel_of(lv, lp.u, lp.v);
  if (pcf_radius == 0) return d <= eval.depth(lv, x, y) ? 1.0f : 0.0f;
  return eval.pcf(lv, x, y, 2 * pcf_radius + 1, d);
}

bool filtered_lookup(const Receiver& r, const LightSpace& light, uint32_t map_level, LightPoint& lp,
                     ReceiverPlane& plane) {
  return receiver_plane_at(light, map_level, r.pos, r.normal, r.closed, lp, plane);
}

float map_visibility_filtered(const Evaluator& eval, const Receiver& r, const LightSpace& light, uint32_t pcf_radius,
                              float footprint) {
  if (!r.hit || r.n_dot_l <= 0) return 0;
  LightPoint lp;
  ReceiverPlane plane;
  if (!filtered_lookup(r, light, eval.finest_level(), lp, plane)) return 1;
  return pcf_footprint_plane(eval, lp.u, lp.v, plane, footprint, 2 * pcf_radius + 1);
}

namespace {

// The constants of lookup_point and a sun's LightSpace::to_light at one level, read once
// per batch.
struct SunTransform {
  Vec3d org, au, av, fw;
  double e, near, depth, texel, k_closed, k_open, side;
  uint32_t level, kr;
};

SunTransform sun_transform(const LightSpace& light, uint32_t level, uint32_t pcf_radius) {
  SunTransform t;
  t.org = light.origin(), t.au = light.axis_u(), t.av = light.axis_v(), t.fw = light.forward();
  t.e = light.extent_uv(), t.near = light.near_plane(), t.depth = light.far_plane() - light.near_plane();
  t.texel = light.extent_uv() / double(uint64_t(1) << level);  // lookup_point's, for a sun
  t.k_closed = kClosedReceiverOffsetTexels + pcf_radius, t.k_open = kOpenReceiverOffsetTexels + pcf_radius;
  t.side = double(uint64_t(1) << level);
  t.level = level, t.kr = 2 * pcf_radius + 1;
  return t;
}

// One receiver: lookup_point's p + normal * k * texel, then to_light, operation for
// operation in the same order (the same IEEE doubles: contraction is off, see
// filter_level.hpp and tiles/CMakeLists.txt), the in-map test, and the texel. (u, v) in
// [0, 1): u * 2^level is exact and below 2^level, so truncating it is
// LightSpace::texel_of's floor, without its library calls. False outside the map.
inline bool sun_tap_one(const SunTransform& t, const Receiver& r, PcfQuery& q) {
  const double k = r.closed ? t.k_closed : t.k_open;
  const double rx = (r.pos.x + r.normal.x * k * t.texel) - t.org.x;
  const double ry = (r.pos.y + r.normal.y * k * t.texel) - t.org.y;
  const double rz = (r.pos.z + r.normal.z * k * t.texel) - t.org.z;
  const double u = (rx * t.au.x + ry * t.au.y + rz * t.au.z) / t.e;
  const double v = (rx * t.av.x + ry * t.av.y + rz * t.av.z) / t.e;
  const double d = ((rx * t.fw.x + ry * t.fw.y + rz * t.fw.z) - t.near) / t.depth;
  if (!(u >= 0 && u < 1 && v >= 0 && v < 1)) return false;
  q = {uint64_t(u * t.side), uint64_t(v * t.side), t.level, t.kr, float(d)};
  return true;
}

size_t sun_tap_queries_scalar(const SunTransform& t, const Receiver* rc, size_t n, PcfQuery* q, uint32_t* index) {
  size_t nq = 0;
  for (size_t i = 0; i < n; ++i)
    if (sun_tap_one(t, rc[i], q[nq])) index[nq++] = uint32_t(i);
  return nq;
}

// The packed paths convert texels with a double -> int32 truncation: exact below 2^31.
constexpr uint32_t kPackedMaxLevel = 30;

// The lanes' results into the queries: every lane is written, the count moves only for
// those in the map (no branch on the mask).
inline size_t put_lanes(const SunTransform& t, size_t i, size_t lanes, int inside, const int32_t* tx,
                        const int32_t* ty, const float* d, PcfQuery* q, uint32_t* index, size_t nq) {
  for (size_t l = 0; l < lanes; ++l) {
    q[nq] = {uint64_t(uint32_t(tx[l])), uint64_t(uint32_t(ty[l])), t.level, t.kr, d[l]};
    index[nq] = uint32_t(i + l);
    nq += size_t((inside >> l) & 1);
  }
  return nq;
}

#if defined(__SSE2__)
// Two receivers at a time: packed IEEE double arithmetic gives each lane exactly the
// scalar result (sun_tap_one's operations in its order), and the three divisions per
// receiver, the loop's cost, go two to an instruction.
size_t sun_tap_queries_sse2(const SunTransform& t, const Receiver* rc, size_t n, PcfQuery* q, uint32_t* index) {
  if (t.level > kPackedMaxLevel) return sun_tap_queries_scalar(t, rc, n, q, index);
  const __m128d t2 = _mm_set1_pd(t.texel), e2 = _mm_set1_pd(t.e), near2 = _mm_set1_pd(t.near),
                depth2 = _mm_set1_pd(t.depth), side2 = _mm_set1_pd(t.side), zero = _mm_setzero_pd(),
                one = _mm_set1_pd(1.0);
  const __m128d ox = _mm_set1_pd(t.org.x), oy = _mm_set1_pd(t.org.y), oz = _mm_set1_pd(t.org.z);
  const __m128d aux = _mm_set1_pd(t.au.x), auy = _mm_set1_pd(t.au.y), auz = _mm_set1_pd(t.au.z);
  const __m128d avx = _mm_set1_pd(t.av.x), avy = _mm_set1_pd(t.av.y), avz = _mm_set1_pd(t.av.z);
  const __m128d fwx = _mm_set1_pd(t.fw.x), fwy = _mm_set1_pd(t.fw.y), fwz = _mm_set1_pd(t.fw.z);
  size_t i = 0, nq = 0;
  for (; i + 2 <= n; i += 2) {
    const Receiver& a = rc[i];
    const Receiver& b = rc[i + 1];
    const __m128d k = _mm_set_pd(b.closed ? t.k_closed : t.k_open, a.closed ? t.k_closed : t.k_open);
    const __m128d rx = _mm_sub_pd(
        _mm_add_pd(_mm_set_pd(b.pos.x, a.pos.x), _mm_mul_pd(_mm_mul_pd(_mm_set_pd(b.normal.x, a.normal.x), k), t2)), ox);
    const __m128d ry = _mm_sub_pd(
        _mm_add_pd(_mm_set_pd(b.pos.y, a.pos.y), _mm_mul_pd(_mm_mul_pd(_mm_set_pd(b.normal.y, a.normal.y), k), t2)), oy);
    const __m128d rz = _mm_sub_pd(
        _mm_add_pd(_mm_set_pd(b.pos.z, a.pos.z), _mm_mul_pd(_mm_mul_pd(_mm_set_pd(b.normal.z, a.normal.z), k), t2)), oz);
    const __m128d u =
        _mm_div_pd(_mm_add_pd(_mm_add_pd(_mm_mul_pd(rx, aux), _mm_mul_pd(ry, auy)), _mm_mul_pd(rz, auz)), e2);
    const __m128d v =
        _mm_div_pd(_mm_add_pd(_mm_add_pd(_mm_mul_pd(rx, avx), _mm_mul_pd(ry, avy)), _mm_mul_pd(rz, avz)), e2);
    const __m128d d = _mm_div_pd(
        _mm_sub_pd(_mm_add_pd(_mm_add_pd(_mm_mul_pd(rx, fwx), _mm_mul_pd(ry, fwy)), _mm_mul_pd(rz, fwz)), near2),
        depth2);
    // Ordered compares: NaN is outside, as in the scalar test.
    const int inside = _mm_movemask_pd(_mm_and_pd(_mm_and_pd(_mm_cmpge_pd(u, zero), _mm_cmplt_pd(u, one)),
                                                  _mm_and_pd(_mm_cmpge_pd(v, zero), _mm_cmplt_pd(v, one))));
    alignas(16) int32_t tx[4], ty[4];
    alignas(16) float df[4];
    _mm_store_si128(reinterpret_cast<__m128i*>(tx), _mm_cvttpd_epi32(_mm_mul_pd(u, side2)));
    _mm_store_si128(reinterpret_cast<__m128i*>(ty), _mm_cvttpd_epi32(_mm_mul_pd(v, side2)));
    _mm_store_ps(df, _mm_cvtpd_ps(d));  // round to nearest, as float(d)
    nq = put_lanes(t, i, 2, inside, tx, ty, df, q, index, nq);
  }
  for (; i < n; ++i)
    if (sun_tap_one(t, rc[i], q[nq])) index[nq++] = uint32_t(i);
  return nq;
}
#endif

#if defined(__x86_64__) || defined(__i386__)
#define ST_AVX __attribute__((target("avx")))
ST_AVX inline __attribute__((always_inline)) __m256d st_dot3_avx(__m256d rx, __m256d ry, __m256d rz, __m256d x,
                                                                 __m256d y, __m256d z) {
  return _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(rx, x), _mm256_mul_pd(ry, y)), _mm256_mul_pd(rz, z));
}

ST_AVX inline __attribute__((always_inline)) __m256d st_offset_avx(double p0, double p1, double p2, double p3,
                                                                   double n0, double n1, double n2, double n3,
                                                                   __m256d k, __m256d texel, __m256d o) {
  return _mm256_sub_pd(
      _mm256_add_pd(_mm256_set_pd(p3, p2, p1, p0), _mm256_mul_pd(_mm256_mul_pd(_mm256_set_pd(n3, n2, n1, n0), k), texel)),
      o);
}

// Four receivers at a time, the same operations as sun_tap_queries_sse2 (AVX has no
// fused multiply-add, so nothing can contract); chosen at run time (tap_query_path_available).
ST_AVX size_t sun_tap_queries_avx(const SunTransform& t, const Receiver* rc, size_t n, PcfQuery* q,
                                  uint32_t* index) {
  if (t.level > kPackedMaxLevel) return sun_tap_queries_scalar(t, rc, n, q, index);
  const __m256d t4 = _mm256_set1_pd(t.texel), e4 = _mm256_set1_pd(t.e), near4 = _mm256_set1_pd(t.near),
                depth4 = _mm256_set1_pd(t.depth), side4 = _mm256_set1_pd(t.side), zero = _mm256_setzero_pd(),
                one = _mm256_set1_pd(1.0);
  const __m256d ox = _mm256_set1_pd(t.org.x), oy = _mm256_set1_pd(t.org.y), oz = _mm256_set1_pd(t.org.z);
  const __m256d aux = _mm256_set1_pd(t.au.x), auy = _mm256_set1_pd(t.au.y), auz = _mm256_set1_pd(t.au.z);
  const __m256d avx = _mm256_set1_pd(t.av.x), avy = _mm256_set1_pd(t.av.y), avz = _mm256_set1_pd(t.av.z);
  const __m256d fwx = _mm256_set1_pd(t.fw.x), fwy = _mm256_set1_pd(t.fw.y), fwz = _mm256_set1_pd(t.fw.z);
  size_t i = 0, nq = 0;
  for (; i + 4 <= n; i += 4) {
    const Receiver& a = rc[i];
    const Receiver& b = rc[i + 1];
    const Receiver& c = rc[i + 2];
    const Receiver& d = rc[i + 3];
    const __m256d k = _mm256_set_pd(d.closed ? t.k_closed : t.k_open, c.closed ? t.k_closed : t.k_open,
                                    b.closed ? t.k_closed : t.k_open, a.closed ? t.k_closed : t.k_open);
    const __m256d rx = st_offset_avx(a.pos.x, b.pos.x, c.pos.x, d.pos.x, a.normal.x, b.normal.x, c.normal.x,
                                     d.normal.x, k, t4, ox);
    const __m256d ry = st_offset_avx(a.pos.y, b.pos.y, c.pos.y, d.pos.y, a.normal.y, b.normal.y, c.normal.y,
                                     d.normal.y, k, t4, oy);
    const __m256d rz = st_offset_avx(a.pos.z, b.pos.z, c.pos.z, d.pos.z, a.normal.z, b.normal.z, c.normal.z,
                                     d.normal.z, k, t4, oz);
    const __m256d u = _mm256_div_pd(st_dot3_avx(rx, ry, rz, aux, auy, auz), e4);
    const __m256d v = _mm256_div_pd(st_dot3_avx(rx, ry, rz, avx, avy, avz), e4);
    const __m256d dd = _mm256_div_pd(_mm256_sub_pd(st_dot3_avx(rx, ry, rz, fwx, fwy, fwz), near4), depth4);
    // Ordered, non-signalling compares: NaN is outside, as in the scalar test.
    const int inside = _mm256_movemask_pd(
        _mm256_and_pd(_mm256_and_pd(_mm256_cmp_pd(u, zero, _CMP_GE_OQ), _mm256_cmp_pd(u, one, _CMP_LT_OQ)),
                      _mm256_and_pd(_mm256_cmp_pd(v, zero, _CMP_GE_OQ), _mm256_cmp_pd(v, one, _CMP_LT_OQ))));
    alignas(16) int32_t tx[4], ty[4];
    alignas(16) float df[4];
    _mm_store_si128(reinterpret_cast<__m128i*>(tx), _mm256_cvttpd_epi32(_mm256_mul_pd(u, side4)));
    _mm_store_si128(reinterpret_cast<__m128i*>(ty), _mm256_cvttpd_epi32(_mm256_mul_pd(v, side4)));
    _mm_store_ps(df, _mm256_cvtpd_ps(dd));  // round to nearest, as float(d)
    nq = put_lanes(t, i, 4, inside, tx, ty, df, q, index, nq);
  }
  for (; i < n; ++i)
    if (sun_tap_one(t, rc[i], q[nq])) index[nq++] = uint32_t(i);
  return nq;
}
#undef ST_AVX
#endif

}  // namespace

bool tap_query_path_available(TapQueryPath path) {
  switch (path) {
    case TapQueryPath::scalar:
      return true;
    case TapQueryPath::sse2:
#if defined(__SSE2__)
      return true;
#else
      return false;
#endif
    case TapQueryPath::avx:
#if defined(__x86_64__) || defined(__i386__)
      return __builtin_cpu_supports("avx");
#else
      return false;
#endif
    case TapQueryPath::best:
      return true;
  }
  return false;
}

size_t sun_tap_queries(const LightSpace& light, uint32_t level, uint32_t pcf_radius, std::span<const Receiver> rc,
                       PcfQuery* queries, uint32_t* index, TapQueryPath path) {
  assert(light.kind() == LightKind::sun && level < 64);
  const SunTransform t = sun_transform(light, level, pcf_radius);
  if (path == TapQueryPath::best) {
    static const TapQueryPath best = tap_query_path_available(TapQueryPath::avx)    ? TapQueryPath::avx
                                     : tap_query_path_available(TapQueryPath::sse2) ? TapQueryPath::sse2
                                                                                    : TapQueryPath::scalar;
    path = best;
  }
  switch (path) {
#if defined(__x86_64__) || defined(__i386__)
    case TapQueryPath::avx:
      if (tap_query_path_available(TapQueryPath::avx)) return sun_tap_queries_avx(t, rc.data(), rc.size(), queries, index);
      break;
#endif
#if defined(__SSE2__)
    case TapQueryPath::sse2:
      return sun_tap_queries_sse2(t, rc.data(), rc.size(), queries, index);
#endif
    default:
      break;
  }
  return sun_tap_queries_scalar(t, rc.data(), rc.size(), queries, index);
}

namespace {

// The shading of render_view and render_stack_view: sky, ambient + Lambert times
// visibility (times the transmittance per channel, when `trans` holds one RGB per pixel).
void shade_image(const std::vector<Receiver>& rec, const std::vector<float>& v, double ambient, std::vector<float>& img,
                 const std::vector<float>* trans = nullptr) {
  const size_t n = rec.size();
  img.assign(n * 3, 0);
  for (size_t i = 0; i < n; ++i) {
    float* px = &img[3 * i];
    if (!rec[i].hit) {
      px[0] = 0.55f, px[1] = 0.7f, px[2] = 0.9f;  // sky
      continue;
    }
    const double lambert = (1 - ambient) * std::max(0.0, rec[i].n_dot_l) * v[i];
    const float albedo[3] = {rec[i].closed ? 0.8f : 0.6f, rec[i].closed ? 0.78f : 0.7f, rec[i].closed ? 0.72f : 0.55f};
    for (int k = 0; k < 3; ++k)
      px[k] = float(albedo[k] * (ambient + lambert * (trans ? double((*trans)[3 * i + k]) : 1.0)));
  }
}

// The light a receiver gets, as one number for the lit test: the mean over the channels
// of visibility x transmittance.
float light_of(float vis, const float* t) { return vis * ((t[0] + t[1] + t[2]) / 3.0f); }

}  // namespace

RenderResult render_view(const SceneTracer& tracer, const std::vector<Receiver>& rec, const Evaluator& eval,
                         const RenderOptions& o) {
  if (rec.size() != size_t(o.width) * o.height) throw Error("render: receiver count does not match the image size");
  if (o.pcf_radius > (Evaluator::kMaxPcf - 1) / 2) throw Error("render: --pcf must be at most 4");
  RenderResult res;
  res.width = o.width, res.height = o.height;
  const size_t n = rec.size();
  std::vector<float> vis(n, 0), tvis;
  using Clk = std::chrono::steady_clock;
  // The receivers both passes answer, the light-facing ones (the others stay at 0),
  // gathered into one compact list before either pass is timed: the map and the rays are
  // timed over the same receivers read the same way, and neither pays for reading the
  // whole G-buffer (gather_seconds says what that costs). The list goes by screen tiles
  // of kGatherTile^2 pixels, so that consecutive receivers are neighbours in both
  // directions (for the map: more answers from the last walks' regions and resumed walks;
  // the rays read the same list in the same order).
  auto t0 = Clk::now();
  double c0 = process_cpu_seconds();
  constexpr uint32_t kGatherTile = 8;
  std::vector<uint32_t> facing;
  facing.reserve(n);
  for (uint32_t ty = 0; ty < o.height; ty += kGatherTile)
    for (uint32_t tx = 0; tx < o.width; tx += kGatherTile)
      for (uint32_t y = ty; y < std::min(o.height, ty + kGatherTile); ++y)
        for (uint32_t x = tx; x < std::min(o.width, tx + kGatherTile); ++x) {
          const size_t i = size_t(y) * o.width + x;
          if (rec[i].hit && rec[i].n_dot_l > 0) facing.push_back(uint32_t(i));
        }
  std::vector<Receiver> fr(facing.size());
  for (size_t k = 0; k < facing.size(); ++k) fr[k] = rec[facing[k]];
  const size_t m = fr.size();
  std::vector<float> fvis(m, 0), ftvis;
  res.gather_seconds = std::chrono::duration<double>(Clk::now() - t0).count();
  res.gather_cpu_seconds = process_cpu_seconds() - c0;
  t0 = Clk::now();
  c0 = process_cpu_seconds();
  const uint32_t L = eval.finest_level();
  // Lookups in batches (Evaluator::pcf_batch: the client's cache takes its lock and walks
  // the top of its page table once per batch; neighbouring pixels share tiles). With
  // pixel_angle set, each receiver asks two levels and blends them (filter_level.hpp).
  const LightSpace& light = tracer.light();
  const uint32_t kr = 2 * o.pcf_radius + 1;
  const bool sun_fast = light.kind() == LightKind::sun && !(o.pixel_angle > 0);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, m, 4096), [&](const tbb::blocked_range<size_t>& r) {
    // Sub-chunks of kChunk receivers on the stack: nothing allocated per pass. A sun's
    // chunk is one client call of 1024 taps: the call's fixed costs (the shared lock, the
    // kept regions and tile paths starting afresh) spread over four times as many taps.
    constexpr size_t kChunk = 1024;
    PcfQuery queries[kChunk];
    uint32_t index[kChunk];  // the receiver of each query
    float answers[kChunk];
    for (size_t b0 = r.begin(); b0 < r.end(); b0 += kChunk) {
      const size_t b1 = std::min(r.end(), b0 + kChunk);
      if (sun_fast) {
        // A sun at the finest level: lookup_point, to_light and the texel (the same IEEE
        // doubles) for the whole chunk in packed arithmetic (sun_tap_queries); receivers
        // outside the map are lit.
        const size_t nq = sun_tap_queries(light, L, o.pcf_radius, std::span<const Receiver>(fr.data() + b0, b1 - b0), queries,
                             index, o.tap_query_path);
        std::fill(fvis.begin() + ptrdiff_t(b0), fvis.begin() + ptrdiff_t(b1), 1.0f);
        eval.pcf_batch(std::span<const PcfQuery>(queries, nq), std::span<float>(answers, nq));
        for (size_t k = 0; k < nq; ++k) fvis[b0 + index[k]] = answers[k];
        continue;
      }
      if (o.filtered) {  // the map answers from the receivers (RenderOptions::filtered)
        float footprints[kChunk];
        for (size_t i = b0; i < b1; ++i)
          footprints[i - b0] = o.pixel_angle > 0 ? receiver_footprint_world(fr[i], o.pixel_angle) : 0.0f;
        o.filtered(std::span<const Receiver>(fr.data() + b0, b1 - b0), std::span<const float>(footprints, b1 - b0),
                   std::span<float>(fvis.data() + b0, b1 - b0));
        continue;
      }
      // Filtered: each tap against the receiver's plane (filtered_lookup), counted inside
      // the encoding's shared traversal (Evaluator::pcf_on_plane).
      for (size_t i = b0; i < b1; ++i) {
        const Receiver& rc = fr[i];
        FilterLevels f{L, L, 0.0f};
        if (o.pixel_angle > 0) f = filter_levels(L, receiver_footprint_texels(rc, light, L, o.pixel_angle));
        LightPoint lp;
        ReceiverPlane pl;
        if (!filtered_lookup(rc, light, L, lp, pl)) {
          fvis[i] = 1;
          continue;
        }
        const auto tf = LightSpace::texel_of(f.fine, lp.u, lp.v);
        const float a = eval.pcf_on_plane(f.fine, tf[0], tf[1], kr, pl);
        if (f.t == 0.0f) {
          fvis[i] = a;
          continue;
        }
        const auto tc = LightSpace::texel_of(f.coarse, lp.u, lp.v);
        fvis[i] = filter_blend(a, eval.pcf_on_plane(f.coarse, tc[0], tc[1], kr, pl), f.t);
      }
    }
  });
  // Partial occluders: the deep map's transmittance per receiver, per channel (at
  // lookup_point's offset in texels of the deep level), filtered where the render filters.
  std::vector<float> ftrans(o.deep ? 3 * m : 0, 1.0f);
  if (o.deep) {
    const double finest_texel = std::ldexp(1.0, -int(L));  // map units
    tbb::parallel_for(tbb::blocked_range<size_t>(0, m, 1024), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t i = r.begin(); i < r.end(); ++i) {
        const Receiver& rc = fr[i];
        // Never a point lookup (width 0): a deep texel holds its box-filtered coverage, and
        // read as a step it puts every leaf edge on a texel edge; one finest texel or more
        // filters bilinearly between texel centres, which puts the edge where the coverage
        // crosses 1/2 (the forest's map-vs-rays mismatch fell from 1.85% to 1.12% at equal
        // levels: render_deep_test.cpp). The GPU's st_deep_shadow filters the same.
        double width = kr * finest_texel;
        if (o.pixel_angle > 0)
          width = kr * std::max(1.0, double(receiver_footprint_texels(rc, light, L, o.pixel_angle))) * finest_texel;
        const LightPoint lp = deep_lookup_point(rc, light, L, o.deep.level, o.pcf_radius);
        if (!(lp.u >= 0 && lp.u < 1 && lp.v >= 0 && lp.v < 1)) continue;
        const auto t = o.deep.transmittance(lp.u, lp.v, float(lp.d), width);
        for (int c = 0; c < 3; ++c) ftrans[3 * i + c] = t[c];
      }
    });
  }
  res.map_seconds = std::chrono::duration<double>(Clk::now() - t0).count();
  res.map_cpu_seconds = process_cpu_seconds() - c0;
  std::vector<float> fttrans, ttrans;
  if (o.diff) {
    ftvis.assign(m, 0);
    if (tracer.has_partial()) fttrans.assign(3 * m, 1.0f);
    t0 = Clk::now();
    c0 = process_cpu_seconds();
    tbb::parallel_for(tbb::blocked_range<size_t>(0, m, 4096), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t i = r.begin(); i < r.end(); ++i) ftvis[i] = tracer.traced(fr[i]);
    });
    if (tracer.has_partial())
      tbb::parallel_for(tbb::blocked_range<size_t>(0, m, 256), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i < r.end(); ++i) {
          const auto t = tracer.transmittance(fr[i]);
          for (int c = 0; c < 3; ++c) fttrans[3 * i + c] = t[c];
        }
      });
    res.traced_seconds = std::chrono::duration<double>(Clk::now() - t0).count();
    res.traced_cpu_seconds = process_cpu_seconds() - c0;
    tvis.assign(n, 0);
    ttrans.assign(3 * n, 1.0f);
    for (size_t k = 0; k < m; ++k) {
      tvis[facing[k]] = ftvis[k];
      if (!fttrans.empty())
        for (int c = 0; c < 3; ++c) ttrans[3 * facing[k] + c] = fttrans[3 * k + c];
    }
  }
  res.transmittance.assign(3 * n, 1.0f);
  for (size_t k = 0; k < m; ++k) {
    vis[facing[k]] = fvis[k];
    if (!ftrans.empty())
      for (int c = 0; c < 3; ++c) res.transmittance[3 * facing[k] + c] = ftrans[3 * k + c];
  }
  shade_image(rec, vis, o.ambient, res.image, &res.transmittance);
  for (size_t i = 0; i < n; ++i) res.receivers += rec[i].hit && rec[i].n_dot_l > 0;
  if (o.diff) {
    shade_image(rec, tvis, o.ambient, res.traced_image, &ttrans);
    res.diff_image.assign(n * 3, 0);
    double abs_sum = 0;
    for (size_t i = 0; i < n; ++i) {
      float* px = &res.diff_image[3 * i];
      const float g = rec[i].hit ? 0.25f + 0.25f * float(std::max(0.0, rec[i].n_dot_l)) : 0.05f;
      px[0] = px[1] = px[2] = g;
      if (!rec[i].hit || rec[i].n_dot_l <= 0) continue;
      for (int c = 0; c < 3; ++c)
        abs_sum += std::fabs(double(vis[i]) * res.transmittance[3 * i + c] - double(tvis[i]) * ttrans[3 * i + c]) / 3;
      const bool map_lit = light_of(vis[i], &res.transmittance[3 * i]) >= 0.5f;
      const bool ray_lit = light_of(tvis[i], &ttrans[3 * i]) >= 0.5f;
      if (map_lit == ray_lit) continue;
      ++res.differing;
      if (ray_lit) px[0] = 1, px[1] = 0.1f, px[2] = 0.1f;  // map says shadow, rays say lit
      else px[0] = 0.1f, px[1] = 0.3f, px[2] = 1;          // map says lit, rays say shadow
    }
    res.mean_abs_difference = res.receivers ? abs_sum / double(res.receivers) : 0;
  }
  res.visibility = std::move(vis);
  return res;
}

RenderResult render_stack_view(const SceneTracer& tracer, const std::vector<Receiver>& rec,
                               const std::vector<LightSpace>& samples, uint32_t L, const StackMapLookups& map,
                               const StackRenderOptions& o) {
  if (rec.size() != size_t(o.width) * o.height) throw Error("render: receiver count does not match the image size");
  if (samples.empty()) throw Error("render: the light set has no samples");
  if (o.pcf_radius > (Evaluator::kMaxPcf - 1) / 2) throw Error("render: --pcf must be at most 4");
  RenderResult res;
  res.width = o.width, res.height = o.height;
  const size_t n = rec.size();
  const LightSpace& light = tracer.light();
  std::vector<float> vis(n, 0), tvis;
  // The samples read and their weights (StackMap::visibility's a and f).
  const uint32_t ns = uint32_t(samples.size());
  const double s = std::clamp(std::isnan(o.time) ? 0.0 : o.time, 0.0, 1.0) * double(ns - 1);
  const bool at_sample = std::fabs(s - std::nearbyint(s)) <= 1e-9;
  const uint32_t a = at_sample ? uint32_t(std::nearbyint(s)) : uint32_t(std::floor(s));
  const float f = float(s - double(a));
  const uint32_t w0 = o.soft ? 0 : a, w1 = o.soft ? ns - 1 : at_sample ? a : a + 1;
  using Clk = std::chrono::steady_clock;
  auto t0 = Clk::now();
  double c0 = process_cpu_seconds();
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 1024), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i < r.end(); ++i) {
      const Receiver& rc = rec[i];
      if (!rc.hit || rc.n_dot_l <= 0) continue;  // vis 0
      uint32_t level = L;
      float footprint = 0;
      if (o.pixel_angle > 0) {
        level = filter_levels(L, receiver_footprint_texels(rc, light, L, o.pixel_angle)).fine;
        footprint = float(rc.distance * o.pixel_angle);
      }
      // lookup_point's normal offset, kept in world space (each sample projects it).
      const double texel = light.texel_size(rc.pos, level);
      const Vec3d p =
          rc.pos + rc.normal * ((rc.closed ? kClosedReceiverOffsetTexels : kOpenReceiverOffsetTexels) + o.pcf_radius) * texel;
      bool all_face = true;
      for (uint32_t w = w0; w <= w1 && all_face; ++w) all_face = faces(rc, samples[w]);
      if (all_face) {
        vis[i] = map.all(p, footprint);
        continue;
      }
      auto one = [&](uint32_t w) { return faces(rc, samples[w]) ? map.sample(p, w, footprint) : 0.0f; };
      if (o.soft) {
        float sum = 0;
        for (uint32_t w = 0; w < ns; ++w) sum += one(w);
        vis[i] = sum / float(ns);
      } else if (at_sample) {
        vis[i] = one(a);
      } else {
        const float va = one(a), vb = one(a + 1);
        vis[i] = va + f * (vb - va);
      }
    }
  });
  res.map_seconds = std::chrono::duration<double>(Clk::now() - t0).count();
  res.map_cpu_seconds = process_cpu_seconds() - c0;
  if (o.diff) {
    tvis.assign(n, 0);
    t0 = Clk::now();
    c0 = process_cpu_seconds();
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 256), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t i = r.begin(); i < r.end(); ++i) {
        if (o.soft) {
          float sum = 0;
          for (uint32_t w = 0; w < ns; ++w) sum += tracer.traced_toward(rec[i], samples[w]);
          tvis[i] = sum / float(ns);
        } else if (at_sample) {
          tvis[i] = tracer.traced_toward(rec[i], samples[a]);
        } else {
          const float ta = tracer.traced_toward(rec[i], samples[a]), tb = tracer.traced_toward(rec[i], samples[a + 1]);
          tvis[i] = ta + f * (tb - ta);
        }
      }
    });
    res.traced_seconds = std::chrono::duration<double>(Clk::now() - t0).count();
    res.traced_cpu_seconds = process_cpu_seconds() - c0;
  }
  shade_image(rec, vis, o.ambient, res.image);
  for (size_t i = 0; i < n; ++i) res.receivers += rec[i].hit && rec[i].n_dot_l > 0;
  if (o.diff) {
    shade_image(rec, tvis, o.ambient, res.traced_image);
    res.diff_image.assign(n * 3, 0);
    double abs_sum = 0;
    for (size_t i = 0; i < n; ++i) {
      float* px = &res.diff_image[3 * i];
      const float g = rec[i].hit ? 0.25f + 0.25f * float(std::max(0.0, rec[i].n_dot_l)) : 0.05f;
      px[0] = px[1] = px[2] = g;
      if (!rec[i].hit || rec[i].n_dot_l <= 0) continue;
      const float d = vis[i] - tvis[i];
      abs_sum += std::fabs(d);
      res.differing += (vis[i] >= 0.5f) != (tvis[i] >= 0.5f);
      if (d == 0) continue;
      const float m = std::min(1.0f, std::fabs(d));
      // Red: the map darker than the rays; blue: lighter (by how much, not only where).
      if (d < 0) px[0] = g + (1 - g) * m, px[1] = g * (1 - m), px[2] = g * (1 - m);
      else px[0] = g * (1 - m), px[1] = g + (0.3f - g) * m, px[2] = g + (1 - g) * m;
    }
    res.mean_abs_difference = res.receivers ? abs_sum / double(res.receivers) : 0;
  }
  res.visibility = std::move(vis);
  return res;
}

void write_rgb_exr(const std::string& path, uint32_t width, uint32_t height, const std::vector<float>& rgb) {
  if (rgb.size() != size_t(width) * height * 3) throw Error(path + ": image buffer size mismatch");
  const std::string tmp = path + ".tmp";
  try {
    Imf::Header h(static_cast<int>(width), static_cast<int>(height));
    h.compression() = Imf::ZIP_COMPRESSION;
    for (const char* c : {"R", "G", "B"}) h.channels().insert(c, Imf::Channel(Imf::FLOAT));
    Imf::FrameBuffer fb;
    const char* names[3] = {"R", "G", "B"};
    for (int k = 0; k < 3; ++k)
      fb.insert(names[k], Imf::Slice(Imf::FLOAT, const_cast<char*>(reinterpret_cast<const char*>(rgb.data() + k)),
                                     3 * sizeof(float), size_t(width) * 3 * sizeof(float)));
    Imf::OutputFile f(tmp.c_str(), h);
    f.setFrameBuffer(fb);
    f.writePixels(int(height));
  } catch (const std::exception& e) {
    std::filesystem::remove(tmp);
    throw Error(path + ": cannot write EXR: " + e.what());
  }
  std::filesystem::rename(tmp, path);
}

void write_rgb_preview_png(const std::string& path, uint32_t width, uint32_t height, const std::vector<float>& rgb) {
  std::vector<Rgb8> px(size_t(width) * height);
  auto enc = [](float v) { return uint8_t(std::lround(255 * std::pow(std::clamp(v, 0.0f, 1.0f), 1 / 2.2f))); };
  for (size_t i = 0; i < px.size(); ++i) px[i] = {enc(rgb[3 * i]), enc(rgb[3 * i + 1]), enc(rgb[3 * i + 2])};
  write_png(path, width, height, px);
}

}  // namespace st
