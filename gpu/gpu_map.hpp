// GpuMap: a client Map's tile cache mirrored on a Vulkan device, and the GPU evaluators
// over it (gpu/GPU_LAYOUT.md draws the buffers).
//
//   st::gpu::GpuMap gpu(map, {.device = "llvmpipe"});
//   gpu.evaluate(queries, answers);                   // a batch, synchronous
//   uint64_t f = gpu.submit_shadow_pass(gbuffer);     // a frame, asynchronous
//   gpu.wait(f, visibility);                          // its visibility image
//
// The Map's TileCache stays the one authority for LRU and allocation: before each
// submission GpuMap compares every slot with what the device holds and uploads, through
// a staging ring, only the slots that changed (at most upload_budget_bytes per frame; the
// rest follow in later frames and answer coarsely meanwhile), and the page-table words
// that point at them. Nothing is re-uploaded per frame. Uploads are recorded in the
// frame's own command buffer before its dispatch, behind a barrier after every earlier
// dispatch on the queue: a slot is overwritten only once every frame submitted before has
// finished reading it, and a frame sees each page wholly before or wholly after an update.
//
// Feedback (sparse virtual texturing): every pass records the tiles it needed and found
// absent on the device, with the number of queries or pixels that needed each. When the
// frame is collected (wait(), or its ring slot's reuse) those tiles are queued on the
// Map's request queue at priority min(pixels, 65535), so the fetcher follows what the
// GPU sampled.
//
// Answers are bit-exact with the CPU's (Map::depth, Map::pcf, pcf_footprint) for the
// same cache contents; GPU_LAYOUT.md "Exactness" says how.
//
// Stack maps (Map::slices() > 0: shadow-map stacks, a moving sun) use the same mirror: the
// page table carries the stack grid and one light per slice (GPU_LAYOUT.md "The stack
// block"), evaluate() takes GpuStackQuery (bit-exact with Map::slice_depth and the same
// kernels per slice), and the shadow pass answers at ShadowPassInput::time, or the soft
// shadow over all slices (ShadowPassInput::soft), for suns and area lights (perspective
// samples) alike.
//
// Errors: the constructor throws GpuError when no Vulkan device is there or the one asked
// for is not (one line naming the devices present), or a Vulkan call fails (naming the
// call). The CPU path (the Map itself) is never affected. Not thread-safe: one thread
// drives a GpuMap.
#pragma once
#include <cstdint>
#include <memory>
#include <span>
#include <stdexcept>
#include <string>

#include "shadowtile/client.hpp"

namespace st::gpu {

class GpuError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct GpuOptions {
  // Substring of the device's name (vulkaninfo's deviceName), e.g. "llvmpipe" or "H200".
  // Empty: the environment variable SHADOWTILE_VK_DEVICE, else the machine's only device.
  std::string device;
  bool validation = false;                  // VK_LAYER_KHRONOS_validation + a messenger
  uint32_t max_queries = 1u << 16;          // per evaluate() call
  uint32_t max_pixels = 1920u * 1080u;      // per shadow pass
  uint64_t upload_budget_bytes = 16u << 20; // tile bytes uploaded per frame at most
  uint32_t feedback_capacity = 4096;        // distinct absent tiles recorded per frame (power of two)
  uint32_t frames_in_flight = 2;            // 1..4
};

// One query of evaluate(). r == 0: the depth of texel (x, y) of `level`. Else r x r PCF
// (1..9) for `receiver` at texel (x, y) of `level`, or, with level == kLevelFromFootprint,
// at the level pcf_footprint picks for `footprint` with (x, y) a texel of the finest level.
struct GpuQuery {
  uint32_t x = 0, y = 0;
  float receiver = 0;
  float footprint = 1;
  uint32_t r = 1;
  uint32_t level = 0;
};
inline constexpr uint32_t kLevelFromFootprint = 0xFFFFFFFFu;

// One query of evaluate() on a stack map (Map::slices() > 0): the same as GpuQuery in
// slice `slice` of the stack. r == 0: the depth of texel (x, y) of `level` (Map::slice_depth);
// else r x r PCF (1..9) at `level`, or at the level the footprint picks (kLevelFromFootprint,
// (x, y) a texel of the finest level), as StackMap::filtered filters one slice.
struct GpuStackQuery {
  uint32_t x = 0, y = 0;
  uint32_t slice = 0;
  uint32_t level = 0;
  float receiver = 0;
  float footprint = 1;
  uint32_t r = 0;
};

// The G-buffer of a shadow pass: per pixel a world position (x, y, z, w; w == 0: no
// surface, visibility 1) and a normal (x, y, z, unused), row-major, width * height each.
// The receiver is offset by normal_offset world units along the normal. The footprint
// is measured per pixel from its right and lower neighbours, or `footprint` for all.
struct ShadowPassInput {
  std::span<const float> positions, normals;  // 4 floats per pixel
  uint32_t width = 0, height = 0;
  uint32_t kernel = 3;                        // PCF kernel side 1..9
  float normal_offset = 0;
  bool neighbour_footprint = true;
  float footprint = 1;
  // Stack maps only: the light set's time in [0, 1] (clamped; NaN reads as 0), sample w at
  // w / (N - 1). Each of the two nearest slices is filtered in its own light space as a
  // 2D map's pass filters its one; they are blended va + f * (vb - va) (exact at a
  // sample's time: that slice alone), StackLookup::visibility's contract.
  double time = 0;
  // Stack maps only: the soft shadow instead, the average over all N slices (time unused):
  // each slice filtered in its own light space as above, summed in slice order in float,
  // divided by N (StackMap::soft_visibility_filtered's order; gpu/shadow_reference.hpp).
  bool soft = false;
  // Stack maps only: each walk in a tile starts from the deepest node its path shares with
  // the pixel's previous walk in that tile (MH 2016 §3.3's last-sample cache carried over
  // w: consecutive slices, PCF taps and the footprint's two levels), as the CPU's shared
  // walk (MhOctree::along_begin) does; false walks each from the tile's root. The answers
  // are the same bits either way (GPU_LAYOUT.md "The stack block": what each costs).
  bool resume_walks = true;
};

// A stack pass's time (ShadowPassInput::time) as StackMap::visibility takes it: with
// s = clamp(time, 0, 1) * (N - 1), a sample's own time (s within 1e-9 of an integer w)
// reads slice w alone (a == b == w, f == 0); else slices a = floor(s) and b = a + 1 are
// blended with f = float(s - a): va + f * (vb - va).
struct StackTime {
  uint32_t a = 0, b = 0;
  float f = 0;
};
StackTime stack_time(uint32_t slices, double time);

struct FrameStats {
  uint64_t frame = 0;
  double gpu_ms = 0;             // the dispatch, from device timestamps (0 if unsupported)
  uint32_t holes = 0;            // queries/pixels with a tap answered from a coarser level
  uint32_t absent_taps = 0;
  uint32_t feedback_tiles = 0;   // distinct absent tiles recorded
  uint32_t feedback_dropped = 0; // absent tiles the feedback set had no room for
  uint32_t requested = 0;        // of those, newly queued or raised on the Map
  uint32_t slots_uploaded = 0;   // tiles uploaded for this frame
  uint64_t bytes_uploaded = 0;   // tile + page-table bytes
};

struct GpuStats {
  uint64_t frames = 0;
  uint64_t slots_uploaded = 0, bytes_uploaded = 0, page_words_uploaded = 0;
  uint64_t slots_deferred = 0;   // changed slots left for a later frame (budget)
  uint64_t feedback_tiles = 0, feedback_requested = 0, feedback_dropped = 0;
  uint64_t holes = 0;
  uint32_t resident_slots = 0;   // slots the device holds now
  uint32_t slot_count = 0;
  uint64_t validation_messages = 0;
  std::string device;
};

class GpuMap {
 public:
  // Throws GpuError (no device, device not found, Vulkan failure, a pool larger than the
  // device's storage-buffer range) or std::runtime_error for an invalid Map.
  GpuMap(client::Map map, GpuOptions options = {});
  ~GpuMap();
  GpuMap(const GpuMap&) = delete;
  GpuMap& operator=(const GpuMap&) = delete;

  // Answers `queries` into `out` (same size, <= max_queries); waits for the device.
  FrameStats evaluate(std::span<const GpuQuery> queries, std::span<float> out);
  // The same, asynchronous: returns the frame number for wait().
  uint64_t submit_evaluate(std::span<const GpuQuery> queries);
  // Stack maps: queries in slices of the stack. Throws GpuError on a 2D map.
  FrameStats evaluate(std::span<const GpuStackQuery> queries, std::span<float> out);
  uint64_t submit_evaluate(std::span<const GpuStackQuery> queries);
  // Submits a shadow pass (width * height <= max_pixels) and returns its frame number;
  // waits only when every ring slot is still in flight. On a stack map, the pass answers
  // at `in.time`, or the soft shadow with `in.soft`, from the stack's tiles (absent cells:
  // the level-K value, and feedback). A 2D map's pass supports suns only (GpuError);
  // `in.soft` on a 2D map is a GpuError.
  uint64_t submit_shadow_pass(const ShadowPassInput& in);
  // Waits for `frame`, copies its visibility image into `out` (width * height floats) and
  // hands its feedback to the Map. Throws GpuError for a frame not in flight.
  FrameStats wait(uint64_t frame, std::span<float> out);

  // Uploads changed slots (within the budget) and waits until the device holds what the
  // cache holds now; returns the slots uploaded. For tests and tools.
  uint32_t sync();
  GpuStats stats() const;
  // The absent tiles the last collected frame's feedback named, with the pixels (or
  // queries) that needed each. Valid until the next frame is collected.
  struct FeedbackTile {
    uint64_t tile = 0;
    uint32_t pixels = 0;
  };
  std::span<const FeedbackTile> last_feedback() const;
  const std::string& device_name() const;
  bool is_stack() const;  // a map of a stack pack: its tiles are MH octree cells

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace st::gpu
