// Rendering a camera view shaded with a shadow map (`shadowtile render` and
// `report`): Embree primary rays find the receivers, simple Lambert shading, and the
// shadow term comes from any st::Evaluator (a pack, a client's tile cache) or, for
// ground truth, from Embree shadow rays toward the light.
//
// Receivers and bias. The map's lit test is receiver_depth <= stored value with the
// stored value inside the texel's dual depth interval [lo, hi] (ARCHITECTURE.md "Definitions").
// A receiver on a light-facing CLOSED surface lies at about lo while hi is where the ray
// leaves the object (MH §3, "dual depth"), so in principle no bias is needed. Measured
// on the city: the bottom-up construction often stores a child's lo itself (MH §3.1 mode
// finding), and a receiver in the far half of that texel on a sloped (relative to the
// light) surface is deeper than the texel-centre lo: 1.9% of pixels self-shadowed with
// no offset. So closed receivers get a small normal offset of kClosedReceiverOffsetTexels
// (half a texel: covers surfaces up to about 45 degrees from facing the light; steeper
// light-facing walls may still show rare acne). A receiver on OPEN
// geometry has hi = lo = its own depth, so an unbiased test self-shadows (acne). For
// those receivers only we offset the lookup point along the (light-facing) normal by
// kOpenReceiverOffsetTexels texels (world size of one finest-level texel): enough to clear the surface's own depth across a texel up
// to slopes of about 60 degrees; open surfaces thinner than that may leak light.
// Surfaces facing away from the light (n.l <= 0) are unlit whatever the map says.
//
// Thread safety: a SceneTracer is built once and is const afterwards (rays may be cast
// from many threads). Errors: st::Error (Embree failure, bad sizes, I/O).
#pragma once
#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "tiles/core/camera.hpp"
#include "tiles/core/deep_format.hpp"
#include "scene/scene.hpp"
#include "tiles/core/evaluator.hpp"
#include "tiles/core/light.hpp"
#include "tiles/core/receiver_plane.hpp"

namespace st {

// kOpenReceiverOffsetTexels, kClosedReceiverOffsetTexels: tiles/core/receiver_plane.hpp.

// What a primary ray found.
struct Receiver {
  bool hit = false;
  bool closed = false;  // on a closed mesh (no bias needed)
  Vec3d pos, normal;    // normal faces the camera side for open meshes, outwards for closed
  double distance = 0;
  double n_dot_l = 0;   // cosine to the light (<= 0: faces away)
};

class SceneTracer {
 public:
  SceneTracer(const Scene& scene, const LightSpace& light);
  ~SceneTracer();
  SceneTracer(const SceneTracer&) = delete;
  SceneTracer& operator=(const SceneTracer&) = delete;

  // Primary rays through pixel centres, row 0 at the top (TBB-parallel over rows); they
  // hit opaque and partial meshes alike, an alpha-tested one only where its texture is
  // solid (volumes are not seen: they only dim the light).
  std::vector<Receiver> primary(const Camera& camera, uint32_t width, uint32_t height) const;
  // Ray-traced visibility of a receiver: 1 if an Embree shadow ray toward the light
  // reaches the light past every opaque mesh, else 0 (partial meshes and volumes are
  // transmittance()'s, as the opaque map leaves them to deep tiles). `offset` moves the
  // ray's start (world units; for supersampled PCF references across a kernel's footprint).
  float traced(const Receiver& r, const Vec3d& offset = {}) const;
  // Ray-traced transmittance of the partial occluders (deep shadow maps, DSM 2000 §3.2)
  // between the light and the receiver, per channel: the light ray through the receiver's
  // point (moved off its surface as traced() moves it) through every partial mesh
  // (transmit, alpha test) and volume (exp(-tau)), one ray, the deep sampler's
  // ray_function evaluated at the receiver's depth. {1, 1, 1} in a scene without partial
  // occluders. The light reaching the receiver is traced() * transmittance() per channel.
  std::array<float, 3> transmittance(const Receiver& r, const Vec3d& offset = {}) const;
  bool has_partial() const;  // the scene has partial meshes or volumes
  // The same shadow ray toward another light (a sample of a light set: stack packs);
  // 0 off surfaces facing away from this tracer's light, as traced().
  float traced_toward(const Receiver& r, const LightSpace& light) const;
  // Direction toward the light from a world point.
  Vec3d to_light(const Vec3d& p) const;
  const LightSpace& light() const { return light_; }

  struct Impl;  // render.cpp (named here for its Embree filter callbacks)

 private:
  std::unique_ptr<Impl> impl_;
  LightSpace light_;
};

// Light-space lookup point of a receiver (with the open-geometry offset); the map's
// answer is eval.lit / pcf at these coordinates.
// PCF compares one receiver depth against (2R+1)^2 texels: on surfaces sloped to the
// light the kernel's far texels lie in front of the receiver, so the offset grows by R
// texels (a normal-offset form of receiver-plane bias).
LightPoint lookup_point(const Receiver& r, const LightSpace& light, uint32_t map_level, uint32_t pcf_radius = 0);

// Light-space lookup point of a receiver in a deep map of level `deep_level`: the
// receiver moved toward the light along the light ray by kDeepDepthBiasTexels texels of
// the deep level, with no normal offset. Moving along the ray keeps (u, v), so the shadow
// is not shifted sideways (on the forest a normal offset of 1.5 texels moved leaf shadows
// by about a texel: 3.7% of receivers differed from the rays at deep level 9 with one of
// deep texels, and an offset of opaque texels put a floor of 0.76% at deep level 12), and
// it clears the receiver's own crossing, whose depth varies across the texel of a sloped
// card. (map_level and pcf_radius are not used; kept for the callers' symmetry.)
inline constexpr double kDeepDepthBiasTexels = deep::kLookupBiasTexels;  // the GPU lookups use it too
LightPoint deep_lookup_point(const Receiver& r, const LightSpace& light, uint32_t map_level, uint32_t deep_level,
                             uint32_t pcf_radius = 0);

// Fraction lit of a receiver by the map: pcf_radius 0 = single tap (exact lit test),
// else a (2r+1)^2 kernel at `level` (default: the finest). Outside the map: lit.
float map_visibility(const Evaluator& eval, const Receiver& r, const LightSpace& light, uint32_t pcf_radius,
                     uint32_t level);

// The lookup of a filtered receiver: the point moved along the normal by the receiver's
// offset (kOpenReceiverOffsetTexels or kClosedReceiverOffsetTexels) in finest texels, no
// more (no PCF radius, no level scale: those were a normal-offset form of the bias that
// moved lookups sideways, across thin open fins), and its receiver plane
// (tiles/core/receiver_plane.hpp): the depth slopes per finest texel from the normal
// through the light's transform (differences of to_light over one texel along the
// surface), each clamped to kMaxReceiverSlope times the depth of one texel along the
// light ray (a surface nearly edge-on to the light). False outside the map (lit).
bool filtered_lookup(const Receiver& r, const LightSpace& light, uint32_t map_level, LightPoint& lp,
                     ReceiverPlane& plane);

// Hierarchical filtering of one receiver (MH §3.3): (2r+1)^2 PCF at the two levels
// filter_levels picks for `footprint` finest-level texels, blended (filter_level.hpp),
// each tap against the receiver plane of filtered_lookup (pcf_footprint_plane); the same
// lookup point and arithmetic as render_view's filtered path.
float map_visibility_filtered(const Evaluator& eval, const Receiver& r, const LightSpace& light, uint32_t pcf_radius,
                              float footprint);

// The side of a receiver's pixel footprint (distance * pixel_angle, seen head-on) in world
// units, as a float (what the client's visibility_filtered takes), and in finest-level
// texels of the map at its position (the input of filter_levels): that float divided by
// the texel's size, as the client divides, so local and served renders pick the same
// levels and blend bit for bit.
float receiver_footprint_world(const Receiver& r, double pixel_angle);
float receiver_footprint_texels(const Receiver& r, const LightSpace& light, uint32_t map_level, double pixel_angle);

// How sun_tap_queries computes: scalar, two receivers per SSE2 instruction, four per AVX
// instruction (an x86 CPU that has it, chosen at run time), or the best this CPU runs.
// Every path gives the same queries bit for bit (tests/tiles/render_tap_queries_test.cpp).
enum class TapQueryPath : uint8_t { best, scalar, sse2, avx };

// Whether this build and CPU run `path` (best and scalar: always; sse2: an SSE2 build;
// avx: an x86 build on a CPU with AVX).
bool tap_query_path_available(TapQueryPath path);

// A sun's single-tap or PCF queries at `level` for receivers rc (all light-facing hits):
// lookup_point(rc[i], light, level, pcf_radius), then the texel of (u, v) and the depth as
// a float, kernel side 2 * pcf_radius + 1: for every receiver whose (u, v) lies in
// [0, 1)^2 (the others are lit), queries[k] and index[k] = i, in receiver order; returns
// k's count. Bit for bit the PcfQuery of lookup_point + LightSpace::texel_of, on every
// path (an unavailable path, or a level above 30 on a packed one, runs scalar).
// queries and index hold rc.size() entries. light.kind() must be LightKind::sun.
size_t sun_tap_queries(const LightSpace& light, uint32_t level, uint32_t pcf_radius, std::span<const Receiver> rc,
                       PcfQuery* queries, uint32_t* index, TapQueryPath path = TapQueryPath::best);

// A map's partial occluders (its deep shadow map, DSM 2000; tiles/core/DEEP.md): the
// per-channel transmittance at light-space (u, v) and depth d, over a footprint `width`
// map units wide (0: the texel under (u, v), DeepMap::transmittance; > 0: filtered with
// the deep tile's mips, DeepMap::filtered). `level` is the deep map's level: a receiver's
// deep lookup point is moved off its surface by lookup_point's offset in texels of that
// level (a coarse deep texel averages the crossing depths of a sloped surface over its
// whole width; deep_lookup_point). Empty `transmittance`: the map has no deep part.
struct DeepLookup {
  uint32_t level = 0;
  std::function<std::array<float, 3>(double u, double v, float d, double width)> transmittance;
  explicit operator bool() const { return bool(transmittance); }
};

struct RenderOptions {
  uint32_t width = 960, height = 540;
  uint32_t pcf_radius = 0;
  // Hierarchical filtering (MH §3.3): > 0, the camera's angle per pixel (radians), picks
  // each receiver's two levels from its footprint and blends them; 0: the finest level.
  double pixel_angle = 0;
  bool diff = false;       // also ray-traced shadows and a difference image
  double ambient = 0.15;
  // A sun's queries (sun_tap_queries): the same answers on every path; tests pick one.
  TapQueryPath tap_query_path = TapQueryPath::best;
  // Partial occluders: the light is visibility x transmittance per channel. The deep
  // lookup filters where the render does: with pixel_angle, over the pixel's footprint
  // times the PCF kernel; with a PCF kernel alone, over the kernel; else one texel.
  DeepLookup deep;
  // A map that answers filtered lookups from the receivers themselves (the client's
  // Map::visibility_filtered with normals: `render --server`). Set, render_view calls it
  // instead of eval's pcf_on_plane wherever that path runs (with pixel_angle, or a light
  // other than a sun): out[i] for rec[i], footprint_world[i] its pixel's side in world
  // units (receiver_footprint_world; 0 without pixel_angle), answered as
  // map_visibility_filtered answers over the same map.
  std::function<void(std::span<const Receiver> rec, std::span<const float> footprint_world, std::span<float> out)>
      filtered;
};

struct RenderResult {
  uint32_t width = 0, height = 0;
  std::vector<float> image;         // RGB, shaded with the map
  std::vector<float> traced_image;  // RGB, shaded with ray-traced shadows (diff only)
  std::vector<float> diff_image;    // RGB: red map-shadowed/traced-lit, blue the reverse
  std::vector<float> visibility;    // per pixel, the opaque map's answer (0 off light-facing surfaces)
  // Per pixel RGB, the deep map's transmittance (1 without a deep part, and off
  // light-facing surfaces): the light is visibility x transmittance per channel.
  std::vector<float> transmittance;
  uint64_t receivers = 0;           // pixels on light-facing surfaces
  // Of those, lit answers that differ (diff only): a receiver is lit when the mean over
  // the channels of visibility x transmittance is at least 0.5 (the rays' the same way).
  uint64_t differing = 0;
  double map_seconds = 0, traced_seconds = 0;
  // The same phases in the process's CPU seconds (all threads): on a busy machine a
  // steadier measure of what each costs than the wall times above. Both passes answer the
  // same gathered list of light-facing receivers (in 8x8-pixel screen tiles), with the
  // same threads and grain; neither includes the gather.
  double map_cpu_seconds = 0, traced_cpu_seconds = 0;
  // Gathering the light-facing receivers from the G-buffer into the compact list both
  // timed passes read (neither pass's time includes it).
  double gather_seconds = 0, gather_cpu_seconds = 0;
  double differing_fraction() const { return receivers ? double(differing) / double(receivers) : 0; }
  double mean_abs_difference = 0;   // over the receivers and channels, |map - traced| light (diff only)
};

RenderResult render_view(const SceneTracer& tracer, const std::vector<Receiver>& receivers, const Evaluator& eval,
                         const RenderOptions& options);

// Stack packs (MH 2016 §4): the view under a light set, at a time or soft. `samples` are
// the set's light spaces (slice w = sample w); the tracer's own light shades (n.l, the
// light-facing test) and sizes the receivers' normal offset, as in render_view (the
// caller passes the sample nearest the time, or the middle sample for soft shadows).
// `map.all(p, footprint)` is the map's answer at the world lookup point p (the receiver
// moved along its normal as lookup_point does), footprint the pixel's side in world units
// (0 without --filter): a StackMap's visibility_filtered / soft_visibility_filtered or the
// client's time_visibility_filtered / soft_visibility_filtered; `map.sample(p, w,
// footprint)` the same for sample w alone. A sample whose light the receiver faces away
// from is unlit whatever the map says (as render_view's n.l <= 0 for one light): where
// every sample read faces the receiver, map.all answers; elsewhere the render combines
// map.sample answers with those samples at 0 (the same blend, the same sum / N). With
// diff, the traced image uses the same samples and weights: at time t,
// (1 - f) * ray(a) + f * ray(a + 1) with StackMap::visibility's a and f (one ray at a
// sample); soft, the mean of N rays (0 toward a sample the receiver faces away from). A
// pixel differs when the two answers fall on opposite sides of 0.5.
struct StackRenderOptions {
  uint32_t width = 960, height = 540;
  uint32_t pcf_radius = 0;
  double pixel_angle = 0;
  bool soft = false;  // else `time`
  double time = 0;
  bool diff = false;
  double ambient = 0.15;
};
struct StackMapLookups {
  std::function<float(const Vec3d& p, float footprint_world)> all;
  std::function<float(const Vec3d& p, uint32_t w, float footprint_world)> sample;
};
RenderResult render_stack_view(const SceneTracer& tracer, const std::vector<Receiver>& receivers,
                               const std::vector<LightSpace>& samples, uint32_t map_level,
                               const StackMapLookups& map, const StackRenderOptions& options);
// Whether a receiver faces a light (n.l > 0 toward it).
bool faces(const Receiver& r, const LightSpace& light);

// RGB float EXR (channels R, G, B; ZIP) and an 8-bit PNG (clamped, sRGB-ish gamma 2.2).
void write_rgb_exr(const std::string& path, uint32_t width, uint32_t height, const std::vector<float>& rgb);
void write_rgb_preview_png(const std::string& path, uint32_t width, uint32_t height, const std::vector<float>& rgb);

}  // namespace st
