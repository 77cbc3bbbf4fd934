// <shadowtile/gpu.hpp>: a client Map's tile cache mirrored on a Vulkan device, and the GPU
// evaluators over it (GPU_LAYOUT.md, installed beside shadowtile.glsl, draws the buffers).
//
// Two modes over the same core (the mirror, the page table, the feedback):
//
// Engine mode (a game's renderer owns instance, device, queue, memory and command buffers,
// the way Dear ImGui's Vulkan backend or NRD enter a renderer):
//
//   st::gpu::EngineDevice dev{instance, physical, device, queue_family,
//                             vkGetInstanceProcAddr, vkGetDeviceProcAddr};
//   st::gpu::GpuMap gpu(map, dev, {.frames_in_flight = 2});
//   // every frame f (the engine's counter), once frame f - frames_in_flight has completed:
//   gpu.retire(completed);                      // reads back feedback of frames <= completed
//   gpu.record_uploads(cmd, f);                 // changed tiles + page-table words, bounded
//   gpu.record_shadow_pass(cmd, f, images, settings);  // or: the engine's own shader that
//                                               // includes shadowtile.glsl, bound with
//                                               // gpu.descriptors(f)
//   gpu.record_end_of_frame(cmd, f);            // feedback made visible to the host
//   // the engine submits cmd on its queue; GpuMap never submits, waits or allocates there.
//
// Own-device mode (tools, tests, `shadowtile view`): GpuMap(map, options) creates its own
// instance, device and queue, takes the G-buffer as host spans and copies visibility back:
//
//   st::gpu::GpuMap gpu(map, {.device = "llvmpipe"});
//   gpu.evaluate(queries, answers);                   // a batch, synchronous
//   uint64_t f = gpu.submit_shadow_pass(gbuffer);     // a frame, asynchronous
//   gpu.wait(f, visibility);                          // its visibility image
//
// The Map's TileCache stays the one authority for LRU and allocation: before each
// submission GpuMap compares the slots that changed since the last one (the cache's change
// journal: O(changes), not O(slots)) with what the device holds and uploads, through
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
// Answers are bit-exact with the CPU's (Map::depth, Map::pcf, Evaluator::pcf_footprint) for the
// same cache contents; GPU_LAYOUT.md "Exactness" says how.
//
// Partial occluders (Map::has_deep: a pack with a deep part, foliage cards, smoke, fog):
// the page table carries the Map's resident deep tiles (GPU_LAYOUT.md "The deep block",
// GpuOptions::deep_bytes), and every 2D path multiplies the visibility by their
// transmittance per channel: shadowtile.glsl's st_shadow, the engine pass's light image
// (ShadowPassImages::light), the own-device pass (wait with light_rgb) and
// evaluate_deep, bit for bit the CPU's deep lookups (point and mip-filtered) for the same
// tiles. Deep tiles come through the feedback like opaque ones: a lookup whose deep tile
// the directory names but the device lacks records it, and GpuMap asks the Map for it
// (FrameStats::deep_wanted); the Map's own lookups and deep_resident fetch them too.
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
#include <vulkan/vulkan.h>

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
  // A 2D map with a deep part (Map::has_deep): page-table bytes reserved for the deep
  // tiles the Map holds (GPU_LAYOUT.md "The deep block"); tiles that do not fit answer
  // transmittance 1 (GpuStats::deep_tiles_dropped counts them).
  uint64_t deep_bytes = 8u << 20;
  // Engine mode: also build the shadow pass that writes ShadowPassImages::light (one more
  // compute pipeline, created in the constructor like the other).
  bool light_pass = false;
  // Engine mode: the pool and the page table are also uniform texel buffers, and GpuMap
  // creates an R32_UINT VkBufferView of each on the engine's device
  // (GpuDescriptors::pool_view, page_table_view) for a shader that includes shadowtile.glsl
  // with ST_TEXEL_BUFFERS defined. Each must fit the device's maxTexelBufferElements (words;
  // 2^27 on lavapipe, at least 2^16 anywhere), else the constructor throws GpuError
  // (max_cache_slots with texel_buffers sizes the cache). Unused in own-device mode.
  bool texel_buffers = false;
};


// ---- engine mode: the engine's device, memory and frames ----

// A buffer with its memory bound, as a GpuAllocator hands it out.
struct GpuBuffer {
  VkBuffer buffer = VK_NULL_HANDLE;
  VkDeviceSize size = 0;
  void* mapped = nullptr;      // host-visible buffers: persistently mapped, host-coherent
  void* allocation = nullptr;  // the allocator's own handle (a VmaAllocation, a VkDeviceMemory, ...)
};

// What a buffer is for: device_local (the slot pool, the page table: written by transfers,
// read by shaders), upload (staging: written by the host each frame, sequentially), readback
// (feedback: written by shaders, read by the host). upload and readback must be HOST_VISIBLE
// | HOST_COHERENT and stay mapped for the buffer's life.
enum class BufferUse : uint32_t { device_local = 0, upload = 1, readback = 2 };

// The memory interface an engine implements (or leaves to the default, one
// vkAllocateMemory per buffer, EngineDevice::allocator == nullptr). GpuMap creates every
// buffer in its constructor and destroys them in its destructor: never on the frame path.
// Called from the thread that constructs or destroys the GpuMap. A Vulkan Memory Allocator
// user backs it in a few lines:
//
//   struct VmaBacked final : st::gpu::GpuAllocator {
//     VmaAllocator vma;
//     VkResult create_buffer(const VkBufferCreateInfo& info, st::gpu::BufferUse use,
//                            st::gpu::GpuBuffer& out) override {
//       VmaAllocationCreateInfo a{};
//       a.usage = VMA_MEMORY_USAGE_AUTO;
//       if (use != st::gpu::BufferUse::device_local) {
//         a.flags = VMA_ALLOCATION_CREATE_MAPPED_BIT |
//                   (use == st::gpu::BufferUse::upload ? VMA_ALLOCATION_CREATE_HOST_ACCESS_SEQUENTIAL_WRITE_BIT
//                                                      : VMA_ALLOCATION_CREATE_HOST_ACCESS_RANDOM_BIT);
//         a.requiredFlags = VK_MEMORY_PROPERTY_HOST_COHERENT_BIT;
//       }
//       VmaAllocationInfo ai{};
//       VmaAllocation alloc = nullptr;
//       const VkResult r = vmaCreateBuffer(vma, &info, &a, &out.buffer, &alloc, &ai);
//       out.size = info.size, out.mapped = ai.pMappedData, out.allocation = alloc;
//       return r;
//     }
//     void destroy_buffer(st::gpu::GpuBuffer& b) noexcept override {
//       vmaDestroyBuffer(vma, b.buffer, static_cast<VmaAllocation>(b.allocation));
//       b = {};
//     }
//   };
class GpuAllocator {
 public:
  virtual ~GpuAllocator() = default;
  // Creates a buffer from `info` (size, usage, exclusive sharing) with memory for `use`
  // bound (and mapped, for upload / readback); VK_SUCCESS or the failure (GpuMap turns it
  // into a GpuError naming the buffer).
  virtual VkResult create_buffer(const VkBufferCreateInfo& info, BufferUse use, GpuBuffer& out) = 0;
  virtual void destroy_buffer(GpuBuffer& buffer) noexcept = 0;
};

// The engine's Vulkan objects. GpuMap borrows them (never destroys them) and loads every
// entry point it calls from the two loaders given, so the engine's loader (or its layer
// chain, or volk) is the one used. The device must be Vulkan 1.2 or later.
struct EngineDevice {
  VkInstance instance = VK_NULL_HANDLE;
  VkPhysicalDevice physical_device = VK_NULL_HANDLE;
  VkDevice device = VK_NULL_HANDLE;
  uint32_t queue_family = 0;  // the family of the queue that runs our recordings (compute or graphics)
  PFN_vkGetInstanceProcAddr get_instance_proc_addr = nullptr;  // required
  PFN_vkGetDeviceProcAddr get_device_proc_addr = nullptr;      // null: loaded from the instance
  const VkAllocationCallbacks* allocation_callbacks = nullptr;  // passed to every vkCreate*/vkDestroy*
  GpuAllocator* allocator = nullptr;  // null: the default; else must outlive the GpuMap
};

// The G-buffer and target of GpuMap::record_shadow_pass, all the engine's image views.
// positions: xyz a world position, w == 0 no surface (visibility 1); normals: xyz the
// normal. Both read with texelFetch through a combined image sampler of our own (nearest,
// unnormalized not needed), so any format the device samples works; the answers are
// bit-exact with the CPU twin for 32-bit float formats (RGBA32F). visibility: an R32F
// storage image in VK_IMAGE_LAYOUT_GENERAL. Width and height: the region written, from
// (0, 0), at most each image's extent.
struct ShadowPassImages {
  VkImageView positions = VK_NULL_HANDLE;
  VkImageView normals = VK_NULL_HANDLE;
  VkImageLayout gbuffer_layout = VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL;
  VkImageView visibility = VK_NULL_HANDLE;
  uint32_t width = 0, height = 0;
  // Optional: an RGBA32F storage image (GENERAL) that also receives the light per channel,
  // rgb = visibility x the deep part's transmittance (1 without one), a = visibility; the
  // same barriers as `visibility`. VK_NULL_HANDLE: not written. Needs
  // GpuOptions::light_pass (else record_shadow_pass throws GpuError).
  VkImageView light = VK_NULL_HANDLE;
};

// The shadow pass's settings, ShadowPassInput's without the host spans (same meanings).
struct ShadowPassSettings {
  uint32_t kernel = 3;  // PCF kernel side: odd, 1..9 (else GpuError)
  float normal_offset = 0;
  bool neighbour_footprint = true;
  float footprint = 1;
  double time = 0;      // stack maps
  bool soft = false;    // stack maps
  bool resume_walks = true;
  bool receiver_plane = true;
};

// What GpuMap's buffers are, for the engine's own descriptor sets (shadowtile.glsl binds
// them at the set and bindings the engine defines). All three are storage buffers; the
// feedback range is the frame's own (its ring slot's). With GpuOptions::texel_buffers the
// pool and page table are also R32_UINT texel-buffer views (VK_NULL_HANDLE without):
// a shader built with ST_TEXEL_BUFFERS binds pool_view and page_table_view as
// texel_type (VK_DESCRIPTOR_TYPE_UNIFORM_TEXEL_BUFFER, VkWriteDescriptorSet::pTexelBufferView;
// vk_setup::write_texel_buffers) and the feedback as a storage buffer.
struct GpuDescriptors {
  VkDescriptorBufferInfo pool{}, page_table{}, feedback{};
  VkBufferView pool_view = VK_NULL_HANDLE, page_table_view = VK_NULL_HANDLE;
  static constexpr VkDescriptorType texel_type = VK_DESCRIPTOR_TYPE_UNIFORM_TEXEL_BUFFER;
};

// One query of evaluate(). r == 0: the depth of texel (x, y) of `level`. Else r x r PCF
// (r a kernel side: odd, 1..9; evaluate() throws GpuError naming the query otherwise) for `receiver` at texel (x, y) of `level`, or, with level == kLevelFromFootprint,
// at the level pcf_footprint picks for `footprint` with (x, y) a texel of the finest level.
struct GpuQuery {
  uint32_t x = 0, y = 0;
  float receiver = 0;
  float footprint = 1;
  uint32_t r = 1;
  uint32_t level = 0;
};
inline constexpr uint32_t kLevelFromFootprint = 0xFFFFFFFFu;

// One query of evaluate_deep(): the deep part's transmittance at light-space (u, v) (map
// units, [0, 1)) and depth, over a footprint `width` map units wide (0: the texel under
// (u, v); > 0: filtered with the deep tile's mips). The arguments of the CPU's lookup
// (client::CacheView::deep_transmittance, Map::transmittance after its light transform).
struct GpuDeepQuery {
  float u = 0, v = 0;
  float depth = 0;
  float width = 0;
};

// One query of evaluate() on a stack map (Map::slices() > 0): the same as GpuQuery in
// slice `slice` of the stack. r == 0: the depth of texel (x, y) of `level` (Map::slice_depth);
// else r x r PCF (r odd, 1..9, as GpuQuery) at `level`, or at the level the footprint picks (kLevelFromFootprint,
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
  uint32_t kernel = 3;                        // PCF kernel side: odd, 1..9 (else GpuError)
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
  // divided by N (StackMap::soft_visibility_filtered's order; the GPU tests' CPU twin repeats it).
  bool soft = false;
  // Stack maps only: each walk in a tile starts from the deepest node its path shares with
  // the pixel's previous walk in that tile (MH 2016 §3.3's last-sample cache carried over
  // w: consecutive slices, PCF taps and the footprint's two levels), as the CPU's shared
  // walk (MhOctree::along_begin) does; false walks each from the tile's root. The answers
  // are the same bits either way (GPU_LAYOUT.md "The stack block": what each costs).
  bool resume_walks = true;
  // Each PCF tap compares the receiver's plane over its texel (tiles/core/receiver_plane.hpp:
  // the plane through the receiver with the pixel's normal, its slopes clamped to
  // kMaxReceiverSlope texels of depth along the light ray per texel), as the CPU's
  // Map::visibility_filtered with a normal and shadowtile.glsl's st_visibility do: no acne
  // from kernels on surfaces sloped to the light. false: one receiver depth for every tap.
  // Perspective lights (a stack's spots) take one receiver depth either way.
  bool receiver_plane = true;
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

// The CPU twin of shadowtile.glsl's lookup at the receivers an engine's shader used (what
// `shadowtile view --twin` checks a frame with): the shader's float32 light transform of
// each receiver (st_light_uvd; not Map::visibility_filtered's double one, whose texel and
// depth can differ in the last bit), its box test, finest texel, the footprint's two
// levels and kernel x kernel PCF on the Map's cache (Map::pcf; a stack: Map::slice_depth per
// slice), blended as the shader blends: bit for bit its answer for the same cache contents.
// receivers: 4 floats each, xyz the receiver already moved along its normal (st_receiver's
// result) and w the footprint in finest texels; w < 0 or NaN: no lookup, answered NaN.
// slopes (optional): 2 floats each, the receiver plane's (gx, gy) the shader used
// (st_receiver_slope; st_shadow_uvd_plane's taps, tiles/core/receiver_plane.hpp); empty or
// zero: one receiver depth for every tap (a stack map: the same slopes in each slice it
// reads, as st_shadow_uvd_plane given them).
// A 2D map whose light the GPU refuses (not a sun) answers 1, as the shader does.
struct ReceiverLookup {
  uint32_t kernel = 3;                    // PCF kernel side: odd, 1..9 (else NaN, as the shader)
  uint32_t slice_a = 0, slice_b = 0;      // stack maps: slice_a alone when equal, else
  float blend = 0;                        //   va + blend * (vb - va)
  bool soft = false;                      // stack maps: every slice summed in order, then / N
};
void receiver_lookup_reference(const client::Map& map, std::span<const float> receivers, const ReceiverLookup& q,
                               std::span<float> out, std::span<const float> slopes = {});


struct FrameStats {
  uint64_t frame = 0;
  double gpu_ms = 0;             // the dispatch, from device timestamps (0 if unsupported)
  uint32_t holes = 0;            // queries/pixels with a tap answered from a coarser level
  uint32_t absent_taps = 0;
  uint32_t feedback_tiles = 0;   // distinct absent tiles recorded
  uint32_t feedback_dropped = 0; // absent tiles the feedback set had no room for
  uint32_t requested = 0;        // of those, newly queued or raised on the Map
  uint32_t deep_wanted = 0;      // of feedback_tiles, deep tiles (partial occluders) absent
  uint32_t slots_uploaded = 0;   // tiles uploaded for this frame
  uint64_t bytes_uploaded = 0;   // tile + page-table bytes
  // Host <-> device traffic of this frame, by kind (bytes the host wrote to or read from
  // memory the device reads or writes): tile bytes and page-table bytes uploaded (staging),
  // feedback bytes read back (header, key array, claimed records), and the G-buffer in and
  // visibility or answers out, which only the own-device mode moves (engine mode: 0).
  uint64_t tile_bytes = 0, page_bytes = 0, feedback_bytes = 0, host_io_bytes = 0;
};

struct GpuStats {
  uint64_t frames = 0;
  uint64_t slots_uploaded = 0, bytes_uploaded = 0, page_words_uploaded = 0;
  uint64_t slots_deferred = 0;   // changed slots left for a later frame (budget)
  uint64_t feedback_tiles = 0, feedback_requested = 0, feedback_dropped = 0;
  uint64_t holes = 0;
  uint64_t tile_bytes = 0, page_bytes = 0, feedback_bytes = 0, host_io_bytes = 0;  // FrameStats' sums
  uint32_t resident_slots = 0;   // slots the device holds now
  uint32_t deep_tiles = 0;       // deep tiles the device holds now (0: no deep part)
  uint32_t deep_tiles_dropped = 0;  // resident deep tiles that did not fit deep_bytes
  uint32_t slot_count = 0;
  // Device memory of the two shared buffers (the pool's includes a DAG-MH pack's
  // dictionary, after the slots). The page table and the dictionary go up whole once (the own-
  // device constructor, or engine mode's first record_uploads, beyond upload_budget_bytes):
  // plan that frame for it; later frames send only changed 64-word blocks.
  uint64_t pool_bytes = 0, page_table_bytes = 0;
  uint64_t validation_messages = 0;
  std::string device;
};

class GpuMap {
 public:
  // Throws GpuError (no device, device not found, Vulkan failure, a pool larger than the
  // device's storage-buffer range, or than its texel-buffer range with
  // GpuOptions::texel_buffers) or std::runtime_error for an invalid Map.
  GpuMap(client::Map map, GpuOptions options = {});
  ~GpuMap();
  GpuMap(const GpuMap&) = delete;
  GpuMap& operator=(const GpuMap&) = delete;

  // ---- engine mode ----
  // Borrows the engine's device (EngineDevice) and creates, in this call only, the slot
  // pool, the page table, per ring slot a staging and a feedback buffer, and the shadow
  // pass's pipeline. GpuOptions::device and ::validation are unused (the engine chose the
  // device and its layers); max_queries and max_pixels are unused (no host inputs). Throws
  // GpuError as the own-device constructor does. The engine keeps the device alive, and idle
  // as far as our work goes (every recorded frame completed), until the destructor returns.
  GpuMap(client::Map map, const EngineDevice& device, GpuOptions options = {});

  // Sizing a Map's cache for a device, before it is opened: the most cache slots of
  // `slot_bytes` (Map::slot_bytes) whose slot pool, one storage buffer, fits the device's
  // maxStorageBufferRange (2^27 bytes on some devices, lavapipe's; a bigger cache makes the
  // constructors throw). Engine mode: the engine's device; own-device: the device
  // options.device chooses (a short-lived instance and device). Throws GpuError as the
  // constructors do. A DAG-MH pack's dictionary also lies in the pool, after the slots:
  // pass its bytes (MapStats::dictionary_bytes) as dictionary_bytes and the count leaves
  // room for it (0: slots only).
  // texel_buffers (GpuOptions::texel_buffers; the GpuOptions overload reads options'): the
  // pool must also fit maxTexelBufferElements words.
  static uint32_t max_cache_slots(const EngineDevice& device, uint32_t slot_bytes, bool texel_buffers = false,
                                  uint64_t dictionary_bytes = 0);
  static uint32_t max_cache_slots(const GpuOptions& options, uint32_t slot_bytes, uint64_t dictionary_bytes = 0);
  // The same for a storage-buffer range in bytes (kAnyDeviceStorageRange: every device).
  static uint32_t max_cache_slots(uint64_t storage_range, uint32_t slot_bytes, uint64_t dictionary_bytes = 0);
  static constexpr uint64_t kAnyDeviceStorageRange = uint64_t(1) << 27;  // Vulkan's minimum maxStorageBufferRange

  // Frames are the engine's own counter (strictly increasing, any start); frame f uses ring
  // slot f % frames_in_flight. Every command buffer we record into runs on one queue of
  // EngineDevice::queue_family, submitted in frame order.
  //
  // retire(completed): every frame <= `completed` has finished on the device (its fence or
  // timeline value signalled). Reads back those frames' feedback (oldest first) into the
  // Map's request queue, never waiting; returns their FrameStats, valid until the next call
  // (last_feedback() then names the newest retired frame's absent tiles).
  std::span<const FrameStats> retire(uint64_t completed_frame);
  // Records frame f's uploads into `cmd` (outside a render pass): the tiles that changed in
  // the cache (at most upload_budget_bytes; the first frame also the whole page table) and
  // the page-table words pointing at them, from the ring slot's staging buffer, and clears
  // the frame's feedback. Barriers recorded: before the copies, shader reads (vertex,
  // fragment, compute) of earlier commands -> transfer writes; after them, transfer writes ->
  // shader reads and writes (vertex, fragment, compute). So the engine needs none around it,
  // but must record it before any use of our buffers in frame f. GpuError when frame f's
  // ring slot still holds an unretired frame, or f is not after the last frame recorded.
  // Returns the upload half of FrameStats (slots, tile and page-table bytes).
  FrameStats record_uploads(VkCommandBuffer cmd, uint64_t frame);
  // Records the compute shadow pass of frame f (after record_uploads(cmd, f)): reads the
  // G-buffer views and writes `images.visibility`; 2D maps (suns) and stack maps (at
  // settings.time, or soft) with the same answers, bit for bit, as the own-device pass
  // and its CPU twins. The engine provides the image barriers: G-buffer writes -> compute
  // shader reads (images in gbuffer_layout), visibility in GENERAL and earlier accesses of it
  // -> compute shader writes; after it, compute shader writes -> its own reads.
  void record_shadow_pass(VkCommandBuffer cmd, uint64_t frame, const ShadowPassImages& images,
                          const ShadowPassSettings& settings);
  // Records, after the frame's last use of our buffers (our pass or the engine's shaders
  // that include shadowtile.glsl), the barrier that makes the feedback writes visible to
  // the host (shader writes -> host reads), so retire() can read them.
  void record_end_of_frame(VkCommandBuffer cmd, uint64_t frame);
  // The buffers for the engine's own descriptor sets (the feedback range of frame f's
  // ring slot). Valid for the GpuMap's life; the ranges never change.
  GpuDescriptors descriptors(uint64_t frame) const;
  bool engine_mode() const;

  // ---- own-device mode (evaluate, submit_*, wait and sync throw GpuError in engine mode;
  // stats, last_feedback, device_name and is_stack serve both modes) ----
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
  // their entry's value, level K's or a split cell's, and feedback). A 2D map's pass supports suns only (GpuError);
  // `in.soft` on a 2D map is a GpuError.
  uint64_t submit_shadow_pass(const ShadowPassInput& in);
  // Waits for `frame`, copies its visibility image into `out` (width * height floats) and
  // hands its feedback to the Map. Throws GpuError for a frame not in flight.
  FrameStats wait(uint64_t frame, std::span<float> out);
  // The same, and the light per channel (3 floats per pixel, light_rgb): for a 2D map's
  // shadow pass, visibility x the deep part's transmittance (st_deep_shadow at the pixel's
  // surface point, its footprint and kernel: GPU_LAYOUT.md "The deep block"); the
  // visibility repeated for a map without a deep part or a stack map.
  FrameStats wait(uint64_t frame, std::span<float> out, std::span<float> light_rgb);
  // Partial occluders: the deep part's transmittance (3 floats per query, rgb), bit for bit
  // the CPU's lookup for the deep tiles the device holds (those the Map held at the last
  // upload; others answer 1). All 1 for a map without a deep part. Waits for the device.
  FrameStats evaluate_deep(std::span<const GpuDeepQuery> queries, std::span<float> out_rgb);
  bool has_deep() const;  // a 2D map with a deep part (a stack map: never)

  // Uploads changed slots (within the budget) and waits until the device holds what the
  // cache holds now; returns the slots uploaded. For tests and tools.
  uint32_t sync();
  GpuStats stats() const;
  // The absent tiles the last collected frame's feedback named, with the pixels (or
  // queries) that needed each; a deep tile by its pack id (bit 63 set: tiles/PACK.md
  // "Deep tiles"). Valid until the next frame is collected.
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
