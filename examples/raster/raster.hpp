// raster.hpp: a headless Vulkan rasterizer that uses the GPU tile cache as a game engine
// does (engine mode, public API only: <shadowtile/gpu.hpp>, <shadowtile/cache_view.hpp>,
// <shadowtile/client.hpp>, and <shadowtile/vk_setup.hpp> for its own Vulkan objects). It is the core of examples/engine_raster and of
// `shadowtile view`: one home for the renderer, read as an example.
//
// The renderer owns what an engine owns: instance, device, queue, command buffers, fences,
// timestamp queries, vertex buffer, render targets and pipelines. GpuMap borrows its
// device (EngineDevice) and records into its command buffers. Per frame f:
//
//   retire   every frame whose fence has signalled (polled, never waited on) is collected:
//            its pixels and timestamps read, then GpuMap::retire(completed) hands that
//            frame's feedback to the Map's request queue. Only when frame f's ring slot
//            still runs frame f - frames_in_flight does render() wait for it (the ordinary
//            frames-in-flight back-pressure: the GPU is frames_in_flight frames behind).
//   record   GpuMap::record_uploads (the tiles that arrived, bounded per frame), a depth
//            pre-pass, the shading pass (examples/shaders/scene.frag: Lambert times
//            st_shadow from shadowtile.glsl, each pixel shaded once: depth test EQUAL),
//            the colour copied to the frame's readback buffer, then
//            GpuMap::record_end_of_frame; submitted with the slot's fence.
//
// No G-buffer leaves the GPU; nothing is prefetched: tiles stream in because the fragment
// shader's feedback asked for them. Timestamps bracket the uploads, the depth pre-pass and
// the shading pass (the shadow lookups' cost: the pass's time less a pass without them,
// Lookup::none), and the whole frame.
//
// Maps: 2D maps (suns and spots: the light comes from GpuMap's page table) and stack maps
// (a time between two slices, or soft: every slice averaged). Errors: std::runtime_error
// naming the Vulkan call that failed, or st::gpu::GpuError from GpuMap. Not thread-safe.
#pragma once
#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "shadowtile/client.hpp"
#include "shadowtile/gpu.hpp"

namespace st::raster {

// What the shading pass looks up per pixel (the benchmark compares them in one pass).
enum class Lookup : uint32_t {
  none = 0,        // Lambert only (the pass's cost without shadows)
  shadowtile = 1,  // st_shadow / st_shadow_stack over the GPU tile cache
  r32f = 2,        // a plain R32F depth map of the finest level (RasterOptions::r32f), same PCF
};

struct RasterOptions {
  uint32_t width = 960, height = 540;
  std::string device;               // a substring of the device's name; empty: SHADOWTILE_VK_DEVICE, else the first
  uint32_t frames_in_flight = 2;    // 1..4
  uint64_t upload_budget_bytes = 16u << 20;
  uint32_t feedback_capacity = 4096;
  bool readback = true;             // copy each frame's colour to the host (FrameResult::rgba)
  // VK_LAYER_KHRONOS_validation with a messenger counting its warnings and errors
  // (validation_messages(); the first is kept): runtime_error when the layer is absent.
  bool validation = false;
  // Also write, per pixel, the receiver the lookup used (xyz; w the footprint in finest
  // texels, -1 where no lookup ran), the visibility and the receiver plane's slopes (RGBA32F:
  // visibility, gx, gy, 0), read back with the colour:
  // a CPU twin can answer the same lookups (shadowtile view --twin).
  bool twin = false;
  // Lookup::r32f: the finest level of the map as 4^r32f_level floats (row-major); empty:
  // a 1x1 image (Lookup::r32f then answers from it, meaningless).
  uint32_t r32f_level = 0;
  std::span<const float> r32f;
};

// One frame's camera and light.
struct FrameInput {
  std::array<double, 3> eye{}, target{};
  double fov_deg = 60;              // vertical
  // The light to shade toward (n.l): a direction toward a sun, or a point (spot, an area
  // light's samples' mean).
  std::array<double, 3> light{};
  bool light_is_point = false;
  uint32_t kernel = 3;              // PCF side 1..9
  bool filter = true;               // the level pair from each pixel's footprint; false: the finest level
  double texel = 0;                 // one finest texel in world units (the footprint's unit)
  // Stack maps: slices a and b blended by f (gpu::stack_time), or soft (all averaged).
  uint32_t slice_a = 0, slice_b = 0;
  float blend = 0;
  bool soft = false;
  Lookup lookup = Lookup::shadowtile;
};

// A frame the device finished.
struct FrameResult {
  uint64_t frame = 0;
  std::span<const uint8_t> rgba;        // width * height * 4 (readback); valid until the next call
  std::span<const float> receivers;     // twin: 4 floats per pixel
  std::span<const float> visibility;    // twin: 1 float per pixel
  std::span<const float> slopes;        // twin: 2 floats per pixel, the receiver plane's (gx, gy)
  double gpu_frame_ms = 0;              // the frame's command buffer, first to last timestamp
  double gpu_upload_ms = 0, gpu_depth_ms = 0, gpu_shade_ms = 0;
  // Host time in GpuMap's calls on this frame's path: the retire() before recording it, its
  // record_uploads and record_end_of_frame (host_us, the sum; retire_us and uploads_us of it).
  double host_us = 0, retire_us = 0, uploads_us = 0;
  gpu::FrameStats stats;                // GpuMap's (uploads and feedback)
};

class Rasterizer {
 public:
  // `triangles`: 6 floats per corner (position, normal), 3 corners per triangle, world space.
  Rasterizer(client::Map map, std::span<const float> triangles, const RasterOptions& options);
  ~Rasterizer();
  Rasterizer(const Rasterizer&) = delete;
  Rasterizer& operator=(const Rasterizer&) = delete;

  // Records and submits the next frame; returns the frames that completed meanwhile
  // (oldest first), valid until the next call. Waits only for the frame that last used
  // this frame's ring slot.
  std::span<const FrameResult> render(const FrameInput& in);
  // Waits for every frame in flight and returns them (the end of a run).
  std::span<const FrameResult> finish();
  // Waits until the device has run every frame submitted, without collecting them (the
  // next render() or finish() retires them). A benchmark that times the host's frame path
  // on a CPU device (lavapipe) calls it first, so that the device's threads do not take
  // the CPU from the timed calls.
  void wait_idle();

  uint64_t frames() const;                // frames submitted
  uint64_t ring_waits() const;            // render() calls that had to wait for a ring slot
  uint64_t validation_messages() const;   // RasterOptions::validation: warnings and errors so far
  const std::string& first_validation_message() const;
  double retire_host_us_last() const;     // host time of the last GpuMap::retire call
  const std::string& device_name() const;
  gpu::GpuStats stats() const;
  uint32_t width() const;
  uint32_t height() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// A view-projection for Vulkan (clip y down, depth 0..1), column-major, from a camera as
// `shadowtile render --camera` takes it (pixel centres on the same rays).
std::array<float, 16> vulkan_view_projection(const FrameInput& in, double aspect, double near_plane, double far_plane);

}  // namespace st::raster
