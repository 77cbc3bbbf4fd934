// Per-texel visibility functions: see deep_sampler.hpp for the contract.
#include "tiles/bake/deep_sampler.hpp"

#include <embree3/rtcore.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <mutex>
#include <string>

#include "common/error.hpp"
#include "common/hash.hpp"

namespace st {
namespace {

// More crossings than this along one ray is refused (memory per ray stays bounded).
constexpr size_t kMaxCrossings = size_t(1) << 20;
constexpr uint64_t kMaxRegionFunctions = uint64_t(1) << 20;
constexpr uint32_t kMaxSamplesPerSide = 64;

struct RawHit {
  float t;
  uint32_t prim;
  float bu, bv;  // Embree's barycentrics: weights of corners 1 and 2
};

// Embree passes our context pointer to the filter; RTCIntersectContext must come first.
struct HitContext {
  RTCIntersectContext ctx;
  std::vector<RawHit>* hits;
  bool overflow;
};
static_assert(std::is_standard_layout_v<HitContext>);

// All-hits traversal: every candidate is recorded and rejected, so the ray's tfar never
// shrinks and Embree reports every primitive along [tnear, tfar].
void collect_hits(const RTCFilterFunctionNArguments* args) {
  auto* hc = reinterpret_cast<HitContext*>(args->context);
  for (unsigned i = 0; i < args->N; ++i) {
    if (args->valid[i] == 0) continue;
    args->valid[i] = 0;
    if (hc->hits->size() >= kMaxCrossings) {
      hc->overflow = true;
      continue;
    }
    hc->hits->push_back({RTCRayN_tfar(args->ray, args->N, i),
                         RTCHitN_primID(args->hit, args->N, i),
                         RTCHitN_u(args->hit, args->N, i), RTCHitN_v(args->hit, args->N, i)});
  }
}

using D3 = std::array<double, 3>;

struct Vtx {
  double depth;
  D3 t;
};

// Float vertices from double ones: nonincreasing per channel, and of a run of vertices
// that round to one float depth only the first and the last are kept (a step).
VisibilityFunction to_function(const std::vector<Vtx>& in) {
  VisibilityFunction f;
  std::vector<VisVertex> vs;
  vs.reserve(in.size());
  for (const Vtx& v : in) {
    VisVertex o;
    o.depth = float(v.depth);
    for (int c = 0; c < 3; ++c) o.t[c] = float(std::clamp(v.t[c], 0.0, 1.0));
    if (!vs.empty())
      for (int c = 0; c < 3; ++c) o.t[c] = std::min(o.t[c], vs.back().t[c]);
    vs.push_back(o);
  }
  for (size_t i = 0; i < vs.size(); ++i) {
    const float d = vs[i].depth;
    const bool first = i == 0 || vs[i - 1].depth != d;
    const bool last = i + 1 == vs.size() || vs[i + 1].depth != d;
    if (!(first || last)) continue;
    if (!f.vertices.empty() && f.vertices.back() == vs[i]) continue;  // carries nothing
    f.vertices.push_back(vs[i]);
  }
  for (const VisVertex& v : f.vertices)
    if (v.t[1] != v.t[0] || v.t[2] != v.t[0]) f.monochrome = false;
  return f;
}

}  // namespace

double DeepSampleOptions::effective_epsilon() const {
  if (epsilon >= 0) return epsilon;
  const double n = double(samples_per_side) * samples_per_side;
  return 0.25 / std::sqrt(std::max(n, 1.0));
}

struct DeepSampler::Impl {
  LightSpace light;
  Vec3d centre;
  RTCDevice device = nullptr;
  RTCScene rtc = nullptr;
  std::vector<uint32_t> prim_triangle;  // Embree primitive -> scene triangle
  std::vector<uint32_t> triangle_mesh;  // scene triangle -> mesh
  // Per-mesh transmit and alpha texture, copied (the Scene may change after construction
  // only through the caller's fault; volumes and textures are copied for the same reason).
  std::vector<Mesh> meshes;
  std::vector<std::array<Vec2f, 3>> uv;
  std::vector<AlphaTexture> textures;
  std::vector<Volume> volumes;

  ~Impl() {
    if (rtc) rtcReleaseScene(rtc);
    if (device) rtcReleaseDevice(device);
  }

  struct Ray {
    Vec3d origin, dir;  // world
    double t0, t1;      // sun: [0, 1]; spot: [near, far]
  };
  Ray ray_at(double u, double v) const {
    const double e = light.extent_uv();
    if (light.kind() == LightKind::sun) {
      const Vec3d o = light.origin() + light.axis_u() * (u * e) + light.axis_v() * (v * e) +
                      light.forward() * light.near_plane();
      return {o, light.forward() * (light.far_plane() - light.near_plane()), 0.0, 1.0};
    }
    return {light.origin(), light.perspective_dir(u, v), light.near_plane(), light.far_plane()};
  }
  double depth_of(double t) const {
    if (light.kind() == LightKind::sun) return t;
    return (t - light.near_plane()) / (light.far_plane() - light.near_plane());
  }

  struct Scratch {
    std::vector<RawHit> hits;
    std::vector<Vtx> surface;  // (depth, transmit of that crossing)
    std::vector<std::vector<Volume::Step>> steps;
    std::vector<Vtx> volume;  // (depth, total tau)
    std::vector<Vtx> out;
    uint64_t crossings = 0, volume_steps = 0;
  };
  VisibilityFunction sample(double u, double v, Scratch& s) const;
};

DeepSampler::DeepSampler(const Scene& s, const LightSpace& light) : impl_(new Impl) {
  Impl& m = *impl_;
  m.light = light;
  m.meshes = s.meshes;
  m.textures = s.alpha_textures;
  m.volumes = s.volumes;
  for (const AlphaTexture& t : m.textures) t.validate();
  for (const Volume& v : m.volumes) v.validate();
  const size_t nt = s.triangles.size(), nv = s.vertices.size();
  m.triangle_mesh.assign(nt, 0);
  bool any_alpha = false;
  for (size_t k = 0; k < s.meshes.size(); ++k) {
    const Mesh& mesh = s.meshes[k];
    if (uint64_t(mesh.first_triangle) + mesh.triangle_count > nt)
      throw Error("deep sampler: scene '" + s.name + "' mesh '" + mesh.name +
                  "' references triangles past the end");
    if (mesh.alpha_texture >= 0) {
      if (size_t(mesh.alpha_texture) >= m.textures.size())
        throw Error("deep sampler: scene '" + s.name + "' mesh '" + mesh.name +
                    "' names alpha texture " + std::to_string(mesh.alpha_texture) + " of " +
                    std::to_string(m.textures.size()));
      any_alpha = true;
    }
    for (float c : mesh.transmit)
      if (!(c >= 0 && c <= 1))
        throw Error("deep sampler: scene '" + s.name + "' mesh '" + mesh.name +
                    "' has a transmittance outside [0, 1]");
    for (uint32_t i = 0; i < mesh.triangle_count; ++i)
      m.triangle_mesh[mesh.first_triangle + i] = uint32_t(k);
  }
  if (any_alpha) {
    if (s.triangle_uv.size() != nt)
      throw Error("deep sampler: scene '" + s.name + "' has alpha-tested meshes but " +
                  std::to_string(s.triangle_uv.size()) + " UV triangles for " +
                  std::to_string(nt) + " triangles");
    m.uv = s.triangle_uv;
  }
  for (size_t k = 0; k < s.meshes.size(); ++k) {
    const Mesh& mesh = s.meshes[k];
    if (!mesh.partial()) continue;
    for (uint32_t i = 0; i < mesh.triangle_count; ++i) {
      const uint32_t tri = mesh.first_triangle + i;
      for (uint32_t vi : s.triangles[tri])
        if (vi >= nv || !is_finite(s.vertices[vi]))
          throw Error("deep sampler: scene '" + s.name + "' triangle " + std::to_string(tri) +
                      " has a missing or non-finite vertex");
      m.prim_triangle.push_back(tri);
    }
  }
  const Aabb b = s.bounds();
  m.centre = b.empty() ? Vec3d{} : b.center();
  m.device = rtcNewDevice(nullptr);
  if (!m.device) throw Error("deep sampler: embree cannot create a device");
  m.rtc = rtcNewScene(m.device);
  rtcSetSceneFlags(m.rtc, RTCSceneFlags(RTC_SCENE_FLAG_ROBUST |
                                        RTC_SCENE_FLAG_CONTEXT_FILTER_FUNCTION));
  rtcSetSceneBuildQuality(m.rtc, RTC_BUILD_QUALITY_MEDIUM);
  if (!m.prim_triangle.empty()) {
    RTCGeometry g = rtcNewGeometry(m.device, RTC_GEOMETRY_TYPE_TRIANGLE);
    const size_t n = m.prim_triangle.size();
    // Three unshared float vertices per primitive, recentred in double (plus one float of
    // padding: Embree reads 16 bytes per vertex).
    auto* vp = static_cast<float*>(rtcSetNewGeometryBuffer(
        g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), 3 * n + 1));
    auto* ip = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
        g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), n));
    if (!vp || !ip) {
      rtcReleaseGeometry(g);
      throw Error("deep sampler: embree cannot allocate the geometry buffers");
    }
    for (size_t p = 0; p < n; ++p)
      for (int c = 0; c < 3; ++c) {
        const Vec3d q = s.vertices[s.triangles[m.prim_triangle[p]][c]] - m.centre;
        vp[9 * p + 3 * c] = float(q.x), vp[9 * p + 3 * c + 1] = float(q.y);
        vp[9 * p + 3 * c + 2] = float(q.z);
        ip[3 * p + c] = unsigned(3 * p + c);
      }
    vp[9 * n] = vp[9 * n + 1] = vp[9 * n + 2] = 0;
    rtcCommitGeometry(g);
    rtcAttachGeometryByID(m.rtc, g, 0);
    rtcReleaseGeometry(g);
  }
  rtcCommitScene(m.rtc);
  if (rtcGetDeviceError(m.device) != RTC_ERROR_NONE)
    throw Error("deep sampler: embree failed to build scene '" + s.name + "'");
}

DeepSampler::~DeepSampler() = default;

VisibilityFunction DeepSampler::Impl::sample(double u, double v, Scratch& s) const {
  const Ray ray = ray_at(u, v);
  // Surfaces: every crossing of a partial mesh.
  s.hits.clear();
  if (!prim_triangle.empty()) {
    HitContext hc;
    rtcInitIntersectContext(&hc.ctx);
    hc.ctx.filter = collect_hits;
    hc.hits = &s.hits;
    hc.overflow = false;
    RTCRayHit rh;
    const Vec3d o = ray.origin - centre;
    rh.ray.org_x = float(o.x), rh.ray.org_y = float(o.y), rh.ray.org_z = float(o.z);
    rh.ray.dir_x = float(ray.dir.x), rh.ray.dir_y = float(ray.dir.y);
    rh.ray.dir_z = float(ray.dir.z);
    rh.ray.tnear = float(ray.t0), rh.ray.tfar = float(ray.t1);
    rh.ray.time = 0, rh.ray.mask = 0xFFFFFFFFu, rh.ray.id = 0, rh.ray.flags = 0;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(rtc, &hc.ctx, &rh);
    if (hc.overflow)
      throw Error("deep sampler: a ray crosses more than " + std::to_string(kMaxCrossings) +
                  " partial surfaces");
  }
  std::sort(s.hits.begin(), s.hits.end(), [&](const RawHit& a, const RawHit& b) {
    if (a.t != b.t) return a.t < b.t;
    return triangle_mesh[prim_triangle[a.prim]] < triangle_mesh[prim_triangle[b.prim]];
  });
  s.surface.clear();
  uint32_t last_mesh = UINT32_MAX;
  float last_t = -1;
  for (const RawHit& h : s.hits) {
    const uint32_t tri = prim_triangle[h.prim];
    const uint32_t mesh_id = triangle_mesh[tri];
    if (h.t == last_t && mesh_id == last_mesh) continue;  // one crossing through an edge
    last_t = h.t, last_mesh = mesh_id;
    const Mesh& mesh = meshes[mesh_id];
    D3 t{mesh.transmit[0], mesh.transmit[1], mesh.transmit[2]};
    if (mesh.alpha_texture >= 0) {
      const auto& c = uv[tri];
      const float w0 = 1 - h.bu - h.bv;
      const float tu = w0 * c[0].u + h.bu * c[1].u + h.bv * c[2].u;
      const float tv = w0 * c[0].v + h.bu * c[1].v + h.bv * c[2].v;
      if (!textures[size_t(mesh.alpha_texture)].solid(tu, tv)) continue;
    }
    const double d = depth_of(h.t);
    if (!s.surface.empty() && s.surface.back().depth == d) {
      for (int c = 0; c < 3; ++c) s.surface.back().t[c] *= t[c];
    } else {
      s.surface.push_back({d, t});
    }
  }
  s.crossings += s.surface.size();
  // Volumes: total optical depth at the union of every volume's steps, linear between.
  s.volume.clear();
  if (!volumes.empty()) {
    s.steps.resize(volumes.size());
    size_t total = 0;
    for (size_t k = 0; k < volumes.size(); ++k) {
      volumes[k].march(ray.origin, ray.dir, ray.t0, ray.t1, s.steps[k]);
      total += s.steps[k].size();
    }
    s.volume_steps += total;
    if (volumes.size() == 1) {
      for (const Volume::Step& st : s.steps[0])
        s.volume.push_back({depth_of(st.t), {st.tau[0], st.tau[1], st.tau[2]}});
    } else if (total > 0) {
      std::vector<double> at;
      at.reserve(total);
      for (auto& sv : s.steps)
        for (auto& st : sv) at.push_back(st.t);
      std::sort(at.begin(), at.end());
      at.erase(std::unique(at.begin(), at.end()), at.end());
      std::vector<size_t> pos(volumes.size(), 0);
      for (double t : at) {
        D3 tau{0, 0, 0};
        for (size_t k = 0; k < volumes.size(); ++k) {
          const auto& sv = s.steps[k];
          if (sv.empty() || t < sv.front().t) continue;
          size_t& p = pos[k];
          while (p + 1 < sv.size() && sv[p + 1].t <= t) ++p;
          const Volume::Step& a = sv[p];
          if (p + 1 == sv.size()) {
            for (int c = 0; c < 3; ++c) tau[c] += a.tau[c];
            continue;
          }
          const Volume::Step& b = sv[p + 1];
          const double f = (t - a.t) / (b.t - a.t);
          for (int c = 0; c < 3; ++c) tau[c] += a.tau[c] + (b.tau[c] - a.tau[c]) * f;
        }
        s.volume.push_back({depth_of(t), tau});
      }
    }
  }
  // The product (§3.2, Figure 4d): evaluated at the union of vertices, linear between.
  s.out.clear();
  D3 surf{1, 1, 1};
  size_t vi = 0;
  auto tau_at = [&](double d) -> D3 {  // the volume's tau at depth d (vi: first >= d)
    if (s.volume.empty() || vi == 0) return {0, 0, 0};
    if (vi == s.volume.size()) return s.volume.back().t;
    const Vtx& a = s.volume[vi - 1];
    const Vtx& b = s.volume[vi];
    const double f = b.depth > a.depth ? (d - a.depth) / (b.depth - a.depth) : 1.0;
    D3 r;
    for (int c = 0; c < 3; ++c) r[c] = a.t[c] + (b.t[c] - a.t[c]) * f;
    return r;
  };
  auto push = [&](double d, const D3& tau) {
    Vtx o{d, {}};
    for (int c = 0; c < 3; ++c) o.t[c] = surf[c] * std::exp(-tau[c]);
    s.out.push_back(o);
  };
  for (const Vtx& hit : s.surface) {
    while (vi < s.volume.size() && s.volume[vi].depth < hit.depth) {
      push(s.volume[vi].depth, s.volume[vi].t);
      ++vi;
    }
    const D3 tau = tau_at(hit.depth);
    push(hit.depth, tau);
    for (int c = 0; c < 3; ++c) surf[c] *= hit.t[c];
    push(hit.depth, tau);
  }
  for (; vi < s.volume.size(); ++vi) push(s.volume[vi].depth, s.volume[vi].t);
  return to_function(s.out);
}

VisibilityFunction DeepSampler::ray_function(double u, double v) const {
  Impl::Scratch s;
  return impl_->sample(u, v, s);
}

namespace {

void check_options(const DeepSampleOptions& o) {
  if (o.samples_per_side < 1 || o.samples_per_side > kMaxSamplesPerSide)
    throw Error("deep sampler: samples per side must be in [1, " +
                std::to_string(kMaxSamplesPerSide) + "]");
  if (!std::isfinite(o.epsilon))
    throw Error("deep sampler: epsilon must be finite (negative: the paper's default)");
}

// The box-filtered texel: N jittered samples, averaged exactly, optionally compressed.
template <class Sample>
VisibilityFunction texel_function(uint32_t level, uint64_t x, uint64_t y,
                                  const DeepSampleOptions& o, bool compress_it,
                                  std::vector<VisibilityFunction>& samples, Sample&& sample) {
  const uint32_t s = o.samples_per_side;
  const double inv = std::ldexp(1.0, -int(level));
  uint64_t state = mix64(o.seed ^ mix64(uint64_t(level) * 0x9E3779B97F4A7C15ull ^
                                        mix64(x * 0xD1B54A32D192ED03ull ^ mix64(y))));
  samples.resize(size_t(s) * s);
  bool any = false;
  for (uint32_t j = 0; j < s; ++j)
    for (uint32_t i = 0; i < s; ++i) {
      const double ju = (i + unit_random(state)) / s, jv = (j + unit_random(state)) / s;
      VisibilityFunction& f = samples[size_t(j) * s + i];
      f = sample((double(x) + ju) * inv, (double(y) + jv) * inv);
      any = any || !f.vertices.empty();
    }
  if (!any) return {};
  std::vector<const VisibilityFunction*> ptrs;
  ptrs.reserve(samples.size());
  for (const auto& f : samples) ptrs.push_back(&f);
  const std::vector<double> w(samples.size(), 1.0);
  VisibilityFunction avg = average_sweep(ptrs, w);  // DSM 2000 §5.1
  if (!compress_it) return avg;
  return compress(avg, o.effective_epsilon());
}

}  // namespace

VisibilityFunction DeepSampler::texel(uint32_t level, uint64_t x, uint64_t y,
                                      const DeepSampleOptions& options,
                                      bool compress_it) const {
  check_options(options);
  TraceRegion r{level, x, y, 1, 1};
  DepthBoundsTracer::check_region(r);
  Impl::Scratch s;
  std::vector<VisibilityFunction> samples;
  return texel_function(level, x, y, options, compress_it, samples,
                        [&](double u, double v) { return impl_->sample(u, v, s); });
}

DeepRegion DeepSampler::trace(const TraceRegion& region, const DeepSampleOptions& options,
                              DeepSampleStats* stats, bool compress_it) const {
  check_options(options);
  DepthBoundsTracer::check_region(region);
  if (uint64_t(region.width) * region.height > kMaxRegionFunctions)
    throw Error("deep sampler: a region holds at most " + std::to_string(kMaxRegionFunctions) +
                " texels");
  const auto t0 = std::chrono::steady_clock::now();
  DeepRegion out;
  out.region = region;
  out.functions.resize(size_t(region.width) * region.height);
  DeepSampleStats total;
  std::mutex mu;
  tbb::parallel_for(tbb::blocked_range<uint32_t>(0, region.height, 1),
                    [&](const tbb::blocked_range<uint32_t>& rows) {
    Impl::Scratch s;
    std::vector<VisibilityFunction> samples;
    DeepSampleStats st;
    for (uint32_t j = rows.begin(); j < rows.end(); ++j)
      for (uint32_t i = 0; i < region.width; ++i) {
        const uint64_t x = region.x0 + i, y = region.y0 + j;
        VisibilityFunction avg = texel_function(
            region.level, x, y, options, false, samples,
            [&](double u, double v) { return impl_->sample(u, v, s); });
        st.vertices_in += avg.vertices.size();
        VisibilityFunction& f = out.functions[size_t(j) * region.width + i];
        f = compress_it ? compress(avg, options.effective_epsilon()) : std::move(avg);
        st.vertices_out += f.vertices.size();
        st.monochrome += f.monochrome;
        ++st.texels;
        st.rays += samples.size();
      }
    st.crossings = s.crossings, st.volume_steps = s.volume_steps;
    std::lock_guard lock(mu);
    total.texels += st.texels, total.rays += st.rays, total.crossings += st.crossings;
    total.volume_steps += st.volume_steps, total.vertices_in += st.vertices_in;
    total.vertices_out += st.vertices_out, total.monochrome += st.monochrome;
  });
  total.seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (stats) *stats = total;
  return out;
}

}  // namespace st
