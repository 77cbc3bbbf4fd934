// GpuMap: the mirror of a client Map's tile cache on a Vulkan device and the frames that
// read it (gpu_map.hpp says what; GPU_LAYOUT.md draws the buffers).
#include "gpu/gpu_map.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cstring>
#include <utility>
#include <vector>

#include "shadowtile/cache_view.hpp"
#include "gpu/gpu_deep.hpp"
#include "gpu/kernels.hpp"
#include "gpu/layout.hpp"
#include "gpu/shadow_reference.hpp"
#include "gpu/tile_slot_table.hpp"
#include "gpu/vk_context.hpp"
#include "tiles/core/morton.hpp"
#include "tiles/core/tile_cache.hpp"
#include "tiles/core/tile_cut_grid.hpp"

namespace st::gpu {

namespace L = layout;

namespace {

constexpr uint32_t kGridMagicWord = 0x52475453u;  // "STGR": a serialized CutGrid (index tile)
constexpr uint32_t kDirtyBlockWords = 64;
// Regions per vkCmdCopyBuffer call (GpuMap::Impl::record_copies).
constexpr uint32_t kRegionsPerCall = 25;

uint32_t align4(uint32_t n) { return (n + 3u) & ~3u; }
// Slots are whole 16-byte quads: shaders may read the pool as uvec4s (st_eval.glsl's ST_POOL4).
uint32_t align16(uint32_t n) { return (n + 15u) & ~15u; }

// PCF takes the kernel side everywhere (client.hpp "PCF"): odd, 1..9. A shadow pass's
// kernel must be one; a query's r is one, or 0 for the depth.
void check_kernel(const char* where, uint32_t kernel) {
  if (!client::pcf_side_valid(kernel))
    throw GpuError(std::string(where) + ": kernel " + std::to_string(kernel) +
                   " is not a PCF kernel side (odd, 1..9)");
}
template <typename Query>
void check_query_kernels(std::span<const Query> queries) {
  for (size_t i = 0; i < queries.size(); ++i)
    if (queries[i].r != 0 && !client::pcf_side_valid(queries[i].r))
      throw GpuError("GpuMap::evaluate: query " + std::to_string(i) + ": r " + std::to_string(queries[i].r) +
                     " is neither 0 (the depth) nor a PCF kernel side (odd, 1..9)");
}

}  // namespace

struct GpuMap::Impl {
  struct Frame {
    // input, normals, output: device-local (what the dispatch reads and writes); the
    // *_host twins are host-visible and copied in the frame's command buffer.
    VkBufferBox staging, input, normals, output, feedback, input_host, normals_host, output_host;
    uint64_t input_bytes = 0, normals_bytes = 0;
    VkCommandBuffer cmd = VK_NULL_HANDLE;
    VkFence fence = VK_NULL_HANDLE;
    VkDescriptorSet set = VK_NULL_HANDLE;
    bool in_flight = false;  // own mode: submitted, fence not waited; engine mode: recorded, not retired
    bool collected = true;
    bool pass_recorded = false;  // engine mode: this frame's shadow pass (one per frame: its set)
    uint64_t frame = 0;
    uint32_t count = 0;  // outputs
    uint32_t out_words = 1;  // per output: 4 when a deep pass writes rgb after the answers
    FrameStats stats;
  };

  client::Map map;
  std::unique_ptr<client::CacheView> view;  // the Map's cache through its published view
  const client::StackTables* sg = nullptr;  // a stack map's grid, else null
  GpuOptions opt;
  uint32_t map_level = 0, k = 0, encoding = 0, slot_count = 0, slot_bytes = 0, slot_words = 0;
  uint64_t pool_bytes = 0;
  uint32_t dict_at = 0, dict_words = 0;  // the DAG-MH dictionary in the pool, after the slots (0, 0: none)
  std::unique_ptr<VkContext> ctx;
  bool engine = false;  // engine mode: the engine's device, recordings only
  Kernels kernels;
  // Engine mode: the compute shadow pass over the engine's images (engine_shadow_pass.comp).
  VkSampler ep_sampler = VK_NULL_HANDLE;
  VkDescriptorSetLayout ep_set_layout = VK_NULL_HANDLE;
  VkPipelineLayout ep_layout = VK_NULL_HANDLE;
  VkPipeline ep_pipeline = VK_NULL_HANDLE;
  VkPipeline ep_light_pipeline = VK_NULL_HANDLE;  // the same, also writing ShadowPassImages::light
  VkDescriptorPool ep_pool = VK_NULL_HANDLE;
  VkPipelineStageFlags shader_stages = VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT;  // stages that may read our buffers
  bool page_table_sent = false;  // engine mode: the first record_uploads sends the whole page table
  bool any_recorded = false;
  uint64_t last_recorded = 0;
  std::vector<FrameStats> retired;  // retire()'s answer (capacity frames_in_flight)
  VkBufferBox pool, page;
  VkBufferView pool_view = VK_NULL_HANDLE, page_view = VK_NULL_HANDLE;  // GpuOptions::texel_buffers
  VkCommandPool cmd_pool = VK_NULL_HANDLE;
  VkQueryPool queries = VK_NULL_HANDLE;
  std::vector<Frame> frames;
  uint64_t next_frame = 1;

  // ---- the mirror (what the device holds, as the host last recorded it) ----
  std::vector<uint32_t> page_shadow;     // the page-table buffer's contents
  std::vector<uint64_t> dirty;           // a bit per kDirtyBlockWords block of page_shadow
  std::vector<uint32_t> dirty_list;
  std::vector<TileId> mirror_tile;       // per slot: the tile the device holds, or kInvalidTile
                                         // (the view's `known`: may run ahead of the links)
  // Per slot, one 32-byte record, two a cache line (the frame path reads a changed slot's,
  // its parent's and its children's from cold caches: one line each, the tile_slot key
  // check included):
  // - tile: the tile linked in the slot (tile_slot's key for it), else kInvalidTile;
  // - pointer: the page-table word last pointed at its tile (low 32 bits) and, for a word in
  //   a child table, that table's slot's link count then (high 32: a later link of that slot
  //   rewrote its table, so the word no longer speaks for this child); ~0: none. unlink
  //   clears the pointer from here instead of looking for the parent again;
  // - links: link() calls so far; levels: index tile levels d, 0 for an encoded tile.
  struct alignas(32) SlotRec {
    TileId tile = kInvalidTile;
    uint64_t pointer = ~uint64_t(0);
    uint32_t links = 0;
    uint8_t levels = 0;
  };
  static_assert(sizeof(SlotRec) == 32);
  std::vector<SlotRec> slot_recs;
  auto slot_key() const {
    return [this](uint32_t s) { return slot_recs[s].tile; };
  }
  // One changed slot as stage_changes queued it: unlinked (old_tile) and linked (tile) a
  // few changes later, so the lines they read were prefetched meanwhile (the frame path runs
  // on cold caches, and one change's misses depend on each other: bucket, parent, word).
  // Captured while the cache's bytes are readable: an index tile's levels and which of
  // its entries are not constant (the children link looks up).
  struct Change {
    uint32_t slot = 0;
    uint8_t levels = 0;  // an index tile's d, else 0
    bool link = false;   // else the slot only empties (or waits for a later frame)
    TileId old_tile = kInvalidTile, tile = kInvalidTile;
    std::array<uint64_t, 4> live{};  // bit c: entry c of an index tile is not constant
  };
  static constexpr uint32_t kChangeLag = 8;  // changes queued before the oldest is applied
  std::array<Change, kChangeLag> changes;    // a ring: `changes_head`, `changes_count`
  uint32_t changes_head = 0, changes_count = 0;
  TileSlotTable tile_slot;
  std::vector<VkBufferCopy> pool_copies, page_copies;
  std::vector<client::WantedTile> wanted;
  std::vector<client::DeepWant> deep_wanted;
  std::vector<FeedbackTile> feedback;
  std::vector<float> answers;  // evaluate_deep's (unused) first word per query
  GpuStats totals;
  uint32_t resident = 0;
  uint32_t off_coarse = 0, off_entries = 0, off_skip_slots = 0, off_children = 0, off_pcf = 0;
  uint32_t off_stack = 0, off_cell_slots = 0;  // stack maps: the stack block, its slot pointers
  bool deep_part = false;  // a 2D map with a deep part: the deep block (kPtDeep)
  DeepMirror deep;

  Impl(client::Map m, const EngineDevice* e, GpuOptions o) : map(std::move(m)), opt(std::move(o)) {
    if (!map.valid()) throw std::runtime_error("GpuMap: the Map is not open (default-constructed)");
    view = std::make_unique<client::CacheView>(map);
    sg = view->stack();
    deep_part = !sg && view->has_deep();
    if (opt.frames_in_flight < 1 || opt.frames_in_flight > 4) throw GpuError("GpuMap: frames_in_flight must be 1..4");
    if (opt.feedback_capacity < 16 || !std::has_single_bit(opt.feedback_capacity) || opt.feedback_capacity > (1u << 20))
      throw GpuError("GpuMap: feedback_capacity must be a power of two in 16..2^20");
    if (opt.max_queries == 0 || opt.max_pixels == 0) throw GpuError("GpuMap: max_queries and max_pixels must be > 0");
    const client::CacheShape& shape = view->shape();
    map_level = shape.finest_level;
    k = shape.skip_level;
    encoding = shape.encoding;
    slot_count = shape.slot_count;
    slot_bytes = shape.slot_bytes;
    slot_words = align16(slot_bytes) / 4;
    if (slot_count > (1u << 23)) throw GpuError("GpuMap: more than 2^23 cache slots");
    // The pack's DAG-MH dictionary sits in the pool after the last slot (whole quads), so a
    // DAG-MH descent reads [dictionary | tile] node words from one buffer (st_dag_node_word).
    dict_words = uint32_t(view->dictionary().size() / 4);
    dict_at = dict_words == 0 ? 0u : slot_count * slot_words;
    pool_bytes = (uint64_t(slot_count) * slot_words + ((uint64_t(dict_words) + 3) & ~uint64_t(3))) * 4;
    engine = e != nullptr;
    ctx = engine ? std::make_unique<VkContext>(*e) : std::make_unique<VkContext>(opt.device, opt.validation);
    totals.device = ctx->device_name();
    totals.slot_count = slot_count;
    if (pool_bytes > ctx->properties().limits.maxStorageBufferRange)
      throw GpuError("GpuMap: the slot pool (" + std::to_string(pool_bytes) +
                     " bytes, DAG-MH dictionary included) exceeds device '" +
                     ctx->device_name() + "' maxStorageBufferRange (" +
                     std::to_string(ctx->properties().limits.maxStorageBufferRange) + "); use fewer cache slots");
    build_page_table();
    try {
      if (engine) {
        create_engine_objects();
      } else {
        create_device_objects();
        upload_all_page_table();
      }
    } catch (...) {
      release();
      throw;
    }
  }

  ~Impl() { release(); }

  void release() noexcept {
    if (!ctx) return;
    VkDevice d = ctx->device();
    if (!engine) ctx->vk.DeviceWaitIdle(d);  // engine mode: the engine has every frame completed
    const VkAllocationCallbacks* cb = ctx->callbacks();
    if (ep_pipeline) ctx->vk.DestroyPipeline(d, ep_pipeline, cb);
    if (ep_light_pipeline) ctx->vk.DestroyPipeline(d, ep_light_pipeline, cb);
    ep_light_pipeline = VK_NULL_HANDLE;
    if (ep_pool) ctx->vk.DestroyDescriptorPool(d, ep_pool, cb);
    if (ep_layout) ctx->vk.DestroyPipelineLayout(d, ep_layout, cb);
    if (ep_set_layout) ctx->vk.DestroyDescriptorSetLayout(d, ep_set_layout, cb);
    if (ep_sampler) ctx->vk.DestroySampler(d, ep_sampler, cb);
    ep_pipeline = VK_NULL_HANDLE, ep_pool = VK_NULL_HANDLE, ep_layout = VK_NULL_HANDLE;
    ep_set_layout = VK_NULL_HANDLE, ep_sampler = VK_NULL_HANDLE;
    for (Frame& f : frames) {
      for (VkBufferBox* b : {&f.staging, &f.input, &f.normals, &f.output, &f.feedback, &f.input_host, &f.normals_host,
                             &f.output_host})
        ctx->destroy(*b);
      if (f.fence) ctx->vk.DestroyFence(d, f.fence, nullptr);
    }
    frames.clear();
    if (queries) ctx->vk.DestroyQueryPool(d, queries, nullptr);
    queries = VK_NULL_HANDLE;
    if (cmd_pool) ctx->vk.DestroyCommandPool(d, cmd_pool, nullptr);
    cmd_pool = VK_NULL_HANDLE;
    kernels.destroy(*ctx);
    for (VkBufferView* v : {&pool_view, &page_view}) {
      if (*v) ctx->vk.DestroyBufferView(d, *v, ctx->callbacks());
      *v = VK_NULL_HANDLE;
    }
    ctx->destroy(pool);
    ctx->destroy(page);
    ctx.reset();
  }

  // ---- the page table's initial contents: header, skip grid, no slots, PCF quotients ----
  void build_page_table() {
    const std::span<const float> coarse = view->skip_coarse();
    const std::span<const client::CacheEntry> entries = view->skip_entries();
    const uint32_t cells = 1u << (2 * k);
    off_coarse = L::kPtHeaderWords;
    off_entries = off_coarse + uint32_t(CutGrid::coarse_count(k));
    off_skip_slots = off_entries + L::kEntryWords * cells;
    off_children = off_skip_slots + cells;
    off_pcf = off_children + slot_count * L::kChildTableWords;
    // The map preview (tiles/core/map_preview.hpp): answers where a tile is absent.
    const client::PreviewTables pv = view->preview();
    const uint32_t pv_words = pv.mask_words;
    const uint32_t off_preview = off_pcf + L::kMaxPcf * L::kPcfTableStride;
    const uint32_t pv_cells = off_preview + L::kPvHeaderWords + cells;
    const uint32_t pv_cell_words = L::kPvCellHeaderWords + 2 * pv_words;
    const uint32_t pv_values = pv_cells + uint32_t(pv.bases.size()) * pv_cell_words;
    const uint32_t pv_end = pv_values + uint32_t(pv.values.size());  // then the 2D light or the stack block
    const uint32_t light_words = sg ? 0u : L::kStLightWords;  // a 2D map's light (kPtLight)
    const uint32_t deep_at = pv_end + light_words + stack_words();  // then the deep block
    const uint32_t deep_words = DeepMirror::words(deep_part, opt.deep_bytes);
    const uint32_t words = deep_at + deep_words;
    page_shadow.assign(words, 0);
    uint32_t* p = page_shadow.data();
    p[L::kPtDictionary] = dict_at;  // the pool word of the DAG-MH dictionary (stage_dictionary), 0: none
    p[L::kPtMagic] = L::kPageMagic;
    p[L::kPtVersion] = L::kLayoutVersion;
    p[L::kPtMapLevel] = map_level;
    p[L::kPtSkipLevel] = k;
    p[L::kPtEncoding] = encoding;
    p[L::kPtSlotCount] = slot_count;
    p[L::kPtSlotWords] = slot_words;
    p[L::kPtSkipCoarse] = off_coarse;
    p[L::kPtSkipEntries] = off_entries;
    p[L::kPtSkipSlots] = off_skip_slots;
    p[L::kPtChildSlots] = off_children;
    p[L::kPtPcfTable] = off_pcf;
    p[L::kPtPreview] = off_preview;
    p[off_preview + L::kPvLevels] = pv.levels;
    p[off_preview + L::kPvMaskWords] = pv_words;
    p[off_preview + L::kPvCells] = pv_cells;
    p[off_preview + L::kPvValues] = pv_values;
    std::copy(pv.ordinals.begin(), pv.ordinals.end(), p + off_preview + L::kPvHeaderWords);
    for (size_t c = 0; c < pv.bases.size(); ++c) {
      uint32_t* r = p + pv_cells + c * pv_cell_words;
      r[0] = pv.bases[c];
      r[1] = std::bit_cast<uint32_t>(pv.entry_values[c]);
      for (uint32_t i = 0; i < pv_words; ++i) {
        const uint64_t m = pv.masks[c * pv_words + i];
        r[L::kPvCellHeaderWords + 2 * i] = uint32_t(m);
        r[L::kPvCellHeaderWords + 2 * i + 1] = uint32_t(m >> 32);
      }
    }
    for (size_t i = 0; i < pv.values.size(); ++i) p[pv_values + i] = std::bit_cast<uint32_t>(pv.values[i]);
    for (size_t i = 0; i < coarse.size(); ++i) p[off_coarse + i] = std::bit_cast<uint32_t>(coarse[i]);
    for (uint32_t e = 0; e < cells; ++e) {
      p[off_entries + 2 * e] = std::bit_cast<uint32_t>(entries[e].value);
      p[off_entries + 2 * e + 1] = (entries[e].kind & 0xFFu) | (entries[e].index_levels & 0xFFu) << 8;
    }
    std::fill(p + off_skip_slots, p + off_pcf, L::kNoSlot);
    // The CPU's quotient float(lit) / float(r * r) (evaluator.hpp), so the GPU never divides.
    for (uint32_t r = 1; r <= L::kMaxPcf; ++r)
      for (uint32_t lit = 0; lit <= r * r; ++lit)
        p[off_pcf + (r - 1) * L::kPcfTableStride + lit] = std::bit_cast<uint32_t>(float(lit) / float(r * r));
    if (sg) {
      build_stack_block(pv_end);
    } else {
      // The 2D map's light in the page table, so an engine's shader reads it from there
      // (shadowtile.glsl); 0 when the pass refuses the light (GpuError at the pass).
      try {
        const client::LightParams lp = view->light();
        const ShadowLight sl = map_light();
        write_light(pv_end, sl, receiver_slope_cap(LightSpace::from_array(LightKind(lp.kind), lp.params), sl, map_level));
        p[L::kPtLight] = pv_end;
      } catch (const GpuError&) {
        p[L::kPtLight] = 0;
      }
    }
    if (deep_part) deep.init(deep_at, deep_words, p, view->light());
    const uint32_t blocks = (words + kDirtyBlockWords - 1) / kDirtyBlockWords;
    dirty.assign((blocks + 63) / 64, 0);
    dirty_list.reserve(blocks);
    mirror_tile.assign(slot_count, kInvalidTile);
    slot_recs.assign(slot_count, SlotRec{});
    tile_slot.init(slot_count);
    pool_copies.reserve(slot_count);
    page_copies.reserve(blocks);
    wanted.reserve(opt.feedback_capacity);
    deep_wanted.reserve(opt.feedback_capacity);
    feedback.reserve(opt.feedback_capacity);
  }

  void create_device_objects() {
    pool = ctx->make_buffer(pool_bytes, false);
    page = ctx->make_buffer(page_shadow.size() * 4, false);
    const Kernel own[2] = {sg ? Kernel::stack_evaluate : Kernel::evaluate, sg ? Kernel::stack_shadow_pass : Kernel::shadow_pass};
    kernels.create(*ctx, opt.frames_in_flight, own);
    cmd_pool = ctx->make_command_pool(true);
    queries = ctx->make_timestamp_queries(2 * opt.frames_in_flight);
    const uint64_t staging =
        opt.upload_budget_bytes + uint64_t(slot_words) * 4 + page_shadow.size() * 4 + uint64_t(dict_words) * 4;
    const uint64_t query_words = sg ? L::kSqWords : L::kQueryWords;
    const uint64_t in_bytes = std::max<uint64_t>(uint64_t(opt.max_queries) * query_words * 4, uint64_t(opt.max_pixels) * 16);
    // A deep part's passes and queries write rgb after the answers: 4 floats each.
    const uint64_t out_bytes = uint64_t(std::max(opt.max_queries, opt.max_pixels)) * (deep_part ? 16 : 4);
    const uint64_t fb_bytes = (L::kFbHeaderWords + uint64_t(opt.feedback_capacity) * (2 + L::kFbRecordWords)) * 4;
    const uint64_t range = ctx->properties().limits.maxStorageBufferRange;
    if (in_bytes > range || out_bytes > range)
      throw GpuError("GpuMap: max_queries / max_pixels exceed device '" + ctx->device_name() + "' maxStorageBufferRange");
    if (page_shadow.size() * 4 > range)
      throw GpuError("GpuMap: the page table (" + std::to_string(page_shadow.size() * 4) +
                     " bytes: skip grid, map preview, DAG-MH dictionary) exceeds device '" + ctx->device_name() +
                     "' maxStorageBufferRange");
    frames.resize(opt.frames_in_flight);
    for (uint32_t i = 0; i < opt.frames_in_flight; ++i) {
      Frame& f = frames[i];
      f.staging = ctx->make_buffer(staging, true);
      f.input = ctx->make_buffer(in_bytes, false);
      f.normals = ctx->make_buffer(uint64_t(opt.max_pixels) * 16, false);
      f.output = ctx->make_buffer(out_bytes, false);
      f.input_host = ctx->make_buffer(in_bytes, true);
      f.normals_host = ctx->make_buffer(uint64_t(opt.max_pixels) * 16, true);
      f.output_host = ctx->make_buffer(out_bytes, true);
      f.feedback = ctx->make_buffer(fb_bytes, true);
      f.cmd = ctx->allocate_command_buffer(cmd_pool);
      f.fence = ctx->make_fence();
      f.set = kernels.bind(*ctx, i, {pool.buffer, page.buffer, f.input.buffer, f.normals.buffer, f.output.buffer,
                                     f.feedback.buffer});
    }
  }

  // ---- the stack block (stack maps; GPU_LAYOUT.md "The stack block") ----
  uint32_t stack_words() const {
    if (!sg) return 0;
    const client::StackTables& g = *sg;
    const uint32_t K = g.skip_level;
    uint64_t words = L::kStHeaderWords + K;
    for (uint32_t l = 0; l < K; ++l) words += g.coarse[l].size();
    words += (L::kEntryWords + 1) * g.cells.size() + uint64_t(L::kStLightWords) * g.slices;
    if (g.cells.size() > L::kMaxStackCells || words > (uint64_t(1) << 28))
      throw GpuError("GpuMap: the stack grid (" + std::to_string(g.cells.size()) + " cells) is too large");
    return uint32_t(words);
  }

  void build_stack_block(uint32_t at) {
    const client::StackTables& g = *sg;
    const uint32_t K = g.skip_level;
    uint32_t* p = page_shadow.data();
    off_stack = at;
    p[L::kPtStack] = at;
    uint32_t* h = p + at;
    h[L::kStXyLevel] = g.xy_level;
    h[L::kStWLevel] = g.w_level;
    h[L::kStSlices] = g.slices;
    h[L::kStSkipLevel] = K;
    uint32_t o = at + L::kStHeaderWords + K;
    for (uint32_t l = 0; l < K; ++l) {
      h[L::kStHeaderWords + l] = o;
      for (float v : g.coarse[l]) p[o++] = std::bit_cast<uint32_t>(v);
    }
    h[L::kStEntries] = o;
    // A split entry's kind word also names its first child's cell: the children follow
    // level K's cells as blocks, one per split entry in cell order (breadth first,
    // tiles/core/stack_grid.hpp), 2^step_bits(l) of them for a split at level l.
    const moct::Geometry geo{g.xy_level, g.w_level};
    std::vector<uint8_t> level(g.cells.size(), uint8_t(K));
    uint64_t next = uint64_t(1) << (2 * geo.xy_bits(K) + geo.w_bits(K));
    for (size_t c = 0; c < g.cells.size(); ++c) {
      const client::CacheEntry& e = g.cells[c];
      uint32_t kind = e.kind;
      if (e.kind == L::kStKindSplit) {
        const uint32_t l = level[c];
        const uint64_t children = uint64_t(1) << geo.step_bits(l);
        if (l >= geo.depth() || next + children > g.cells.size())  // the grid's parser refuses both
          throw GpuError("GpuMap: the stack grid's split cell " + std::to_string(c) + " has no children");
        kind |= uint32_t(next) << L::kStFirstChildShift;
        std::fill(level.begin() + ptrdiff_t(next), level.begin() + ptrdiff_t(next + children), uint8_t(l + 1));
        next += children;
      }
      p[o++] = std::bit_cast<uint32_t>(e.value);
      p[o++] = kind;
    }
    h[L::kStCellSlots] = off_cell_slots = o;
    for (size_t c = 0; c < g.cells.size(); ++c) p[o++] = L::kNoSlot;
    h[L::kStLights] = o;
    for (uint32_t w = 0; w < g.slices; ++w, o += L::kStLightWords) {
      const LightSpace ls = LightSpace::from_array(LightKind(g.lights[w].kind), g.lights[w].params);
      const ShadowLight sl = shadow_light(ls);  // any kind
      write_light(o, sl, receiver_slope_cap(ls, sl, g.xy_level));
    }
  }

  // The 2D map's light as the pass projects it (suns only: GpuError for any other kind).
  ShadowLight map_light() const {
    const client::LightParams lp = view->light();
    const auto kind = LightKind(lp.kind);
    if (kind != LightKind::sun && kind != LightKind::sun_ground)
      throw GpuError("GpuMap: the GPU shadow pass supports sun lights only");
    return shadow_light(LightSpace::from_array(kind, lp.params));
  }

  // kStLightWords words at `o`: GPU_LAYOUT.md "The stack block" (the 2D light likewise).
  void write_light(uint32_t o, const ShadowLight& sl, float slope_cap) {
    uint32_t* p = page_shadow.data();
    for (int i = 0; i < 3; ++i) {
      p[o + i] = std::bit_cast<uint32_t>(sl.origin[i]);
      p[o + 3 + i] = std::bit_cast<uint32_t>(sl.axis_u[i]);
      p[o + 6 + i] = std::bit_cast<uint32_t>(sl.axis_v[i]);
      p[o + 9 + i] = std::bit_cast<uint32_t>(sl.forward[i]);
    }
    p[o + 12] = std::bit_cast<uint32_t>(sl.near_scaled);
    p[o + L::kStLightCentreU] = std::bit_cast<uint32_t>(sl.centre_u);
    p[o + L::kStLightCentreV] = std::bit_cast<uint32_t>(sl.centre_v);
    p[o + L::kStLightProjection] = sl.perspective ? 1u : 0u;
    p[o + L::kStLightSlopeCap] = std::bit_cast<uint32_t>(slope_cap);
  }

  void upload_all_page_table() {
    Frame& f = frames[0];
    std::memcpy(f.staging.mapped, page_shadow.data(), page_shadow.size() * 4);
    const VkBufferCopy dict = stage_dictionary(f, page_shadow.size() * 4);
    VkCommandBufferBeginInfo bi{};
    bi.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO;
    bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
    vk_check(ctx->vk.BeginCommandBuffer(f.cmd, &bi), "vkBeginCommandBuffer");
    VkBufferCopy all{0, 0, page_shadow.size() * 4};
    ctx->vk.CmdCopyBuffer(f.cmd, f.staging.buffer, page.buffer, 1, &all);
    // The slots zeroed, the dictionary after them (disjoint ranges: no barrier between).
    ctx->vk.CmdFillBuffer(f.cmd, pool.buffer, 0, dict_words ? uint64_t(dict_at) * 4 : VK_WHOLE_SIZE, 0);
    if (dict.size) ctx->vk.CmdCopyBuffer(f.cmd, f.staging.buffer, pool.buffer, 1, &dict);
    vk_check(ctx->vk.EndCommandBuffer(f.cmd), "vkEndCommandBuffer");
    submit_and_wait(f);
  }

  // The pack's DAG-MH dictionary, word for word, into `f`'s staging at byte `off`: the copy
  // that puts it at pool word dict_at (size 0: no dictionary). Sent once, with the first
  // page table; it never changes while the map is open.
  VkBufferCopy stage_dictionary(Frame& f, uint64_t off) {
    const std::span<const uint8_t> dict = view->dictionary();
    if (dict.empty()) return VkBufferCopy{0, 0, 0};
    std::memcpy(static_cast<uint8_t*>(f.staging.mapped) + off, dict.data(), dict.size());  // little-endian words
    return VkBufferCopy{off, uint64_t(dict_at) * 4, dict.size()};
  }

  void submit_and_wait(Frame& f) {
    VkSubmitInfo si{};
    si.sType = VK_STRUCTURE_TYPE_SUBMIT_INFO;
    si.commandBufferCount = 1;
    si.pCommandBuffers = &f.cmd;
    vk_check(ctx->vk.QueueSubmit(ctx->queue(), 1, &si, f.fence), "vkQueueSubmit");
    vk_check(ctx->vk.WaitForFences(ctx->device(), 1, &f.fence, VK_TRUE, UINT64_MAX), "vkWaitForFences");
    vk_check(ctx->vk.ResetFences(ctx->device(), 1, &f.fence), "vkResetFences");
  }

  // ---- the mirror ----
  void set_page_word(uint32_t w, uint32_t v) {
    if (page_shadow[w] == v) return;
    page_shadow[w] = v;
    const uint32_t b = w / kDirtyBlockWords;
    uint64_t& bits = dirty[b / 64];
    const uint64_t bit = uint64_t(1) << (b % 64);
    if (!(bits & bit)) bits |= bit, dirty_list.push_back(b);
  }

  // The page-table word that points at `tile` on the device: its skip cell's slot word,
  // or its entry in the child table of its parent index tile, when the device holds that
  // parent; else ~0u. Found bottom-up through the tile -> slot table (the parent is the
  // resident ancestor at level - j whose index levels are j, j = 1..kMaxIndexLevels: in
  // a pack, no other tile sits on that path), not by walking down from the skip grid:
  // the walk read one child-table word and one kind per level from tables of slot_count *
  // 256 entries (megabytes on a large cache), a cache miss or two per level per tile on
  // the frame path. A parent the device holds but cannot reach yet (its own parent
  // absent) also gets its child's pointer here, as its own link would have found it.
  uint32_t pointer_word(TileId tile) const {
    if (sg) {  // a stack cell's tile: the cell's slot pointer
      uint64_t cell = 0;
      return view->stack_tile_cell(tile, cell) ? off_cell_slots + uint32_t(cell) : ~0u;
    }
    const uint32_t level = tile_level(tile);
    const uint64_t morton = tile_morton(tile);
    if (level < k) return ~0u;
    if (level == k) return off_skip_slots + uint32_t((uint64_t(morton_compact(morton >> 1)) << k) + morton_compact(morton));
    for (uint32_t j = 1; j <= kMaxIndexLevels && j <= level - k; ++j) {
      const uint32_t s = tile_slot.find(tile_parent(tile, j), slot_key());
      if (s == L::kNoSlot || slot_recs[s].levels != j) continue;
      const uint64_t low = tile_child_morton(tile, j);
      const uint32_t c = (morton_compact(low >> 1) << j) + morton_compact(low);
      return off_children + s * L::kChildTableWords + c;
    }
    return ~0u;
  }

  // SlotLinks::pointer's tag of page-table word w.
  uint64_t pointer_tag(uint32_t w) const {
    if (w >= off_children && w < off_pcf) return uint64_t(slot_recs[(w - off_children) / L::kChildTableWords].links) << 32 | w;
    return w;
  }

  void unlink(uint32_t s, TileId t) {
    // The word pointer_word(t) would find (the tile's parent, if the device holds it, set
    // it when the later of the two was linked), unless its child table was rewritten since:
    // no walk up through the tile -> slot table (a cache miss or two per level tried).
    SlotRec& sl = slot_recs[s];
    const uint64_t tag = sl.pointer;
    const uint32_t w = uint32_t(tag);
    if (tag != ~uint64_t(0) && pointer_tag(w) == tag && page_shadow[w] == s) set_page_word(w, L::kNoSlot);
    sl.pointer = ~uint64_t(0);
    // The cache may already have moved the tile to another slot that this pass linked
    // first (slots are compared in index order): that mapping must survive, or an index
    // tile linked later would not find its child and answer coarser than the CPU.
    tile_slot.erase(t, s);
    mirror_tile[s] = kInvalidTile;
    sl.tile = kInvalidTile;
    sl.levels = 0;
    --resident;
  }

  // Slot `c.slot` now holds `c.tile` on the device: point its parent at it, and if it is
  // an index tile, point its entries at those of its children the device holds.
  void link(const Change& c) {
    const uint32_t s = c.slot;
    const TileId tile = c.tile;
    mirror_tile[s] = tile;
    SlotRec& sl = slot_recs[s];
    tile_slot.set(tile, s, slot_key());
    sl.tile = tile;
    ++resident;
    ++sl.links;
    sl.levels = c.levels;
    if (const uint32_t d = c.levels) {
      const TileAddress a = tile_address(tile);
      for (uint32_t e = 0; e < (1u << (2 * d)); ++e) {
        uint32_t ptr = L::kNoSlot;
        if (c.live[e >> 6] >> (e & 63) & 1) {
          const uint32_t cx = (a.x << d) + (e & ((1u << d) - 1)), cy = (a.y << d) + (e >> d);
          ptr = tile_slot.find(make_tile_id(a.level + d, cx, cy), slot_key());
        }
        const uint32_t w = off_children + s * L::kChildTableWords + e;
        set_page_word(w, ptr);
        if (ptr != L::kNoSlot) slot_recs[ptr].pointer = pointer_tag(w);
      }
    }
    const uint32_t w = pointer_word(tile);
    if (w != ~0u) set_page_word(w, s);
    sl.pointer = w != ~0u ? pointer_tag(w) : ~uint64_t(0);
  }

  // The change as link() reads it: an index tile's levels and live entries from its bytes.
  static void read_index_entries(Change& c, std::span<const uint8_t> b) {
    uint32_t magic = 0, d = 0;
    if (b.size() >= 8) std::memcpy(&magic, b.data(), 4), std::memcpy(&d, b.data() + 4, 4);
    if (magic != kGridMagicWord || d < 1 || d > kMaxIndexLevels) return;
    c.levels = uint8_t(d);
    const size_t entries = 8 + 4 * CutGrid::coarse_count(d);
    for (uint32_t e = 0; e < (1u << (2 * d)); ++e) {
      const uint8_t kind = entries + 8 * e + 4 < b.size() ? b[entries + 8 * e + 4] : 0;
      if (kind != L::kKindConstant) c.live[e >> 6] |= uint64_t(1) << (e & 63);
    }
  }

  // Loads what applying `c` reads first: its slot's record, its buckets (the old tile's,
  // the new tile's, its parent's one level up, its live children's), its child table.
  void prefetch_change(const Change& c) const {
    __builtin_prefetch(&slot_recs[c.slot]);
    if (c.old_tile != kInvalidTile) tile_slot.prefetch(c.old_tile);
    if (!c.link) return;
    tile_slot.prefetch(c.tile);
    if (!sg && tile_level(c.tile) > k) tile_slot.prefetch(tile_parent(c.tile, 1));
    if (const uint32_t d = c.levels) {
      const uint32_t w0 = off_children + c.slot * L::kChildTableWords, n = 1u << (2 * d);
      for (uint32_t e = 0; e < n; e += 16) __builtin_prefetch(&page_shadow[w0 + e]);
      __builtin_prefetch(&dirty[w0 / kDirtyBlockWords / 64]);
      const TileAddress a = tile_address(c.tile);
      for (uint32_t e = 0; e < n; ++e)
        if (c.live[e >> 6] >> (e & 63) & 1)
          tile_slot.prefetch(make_tile_id(a.level + d, (a.x << d) + (e & ((1u << d) - 1)), (a.y << d) + (e >> d)));
    }
  }

  // Applies the oldest queued change (unlink, then link), in the order they were queued.
  void apply_oldest_change() {
    const Change& c = changes[changes_head];
    if (c.old_tile != kInvalidTile) unlink(c.slot, c.old_tile);
    if (c.link) link(c);
    changes_head = (changes_head + 1) % kChangeLag;
    --changes_count;
  }
  // The second look, kChangeLag / 2 changes before `c` is applied, when the lines
  // prefetch_change asked for are in: the words unlink and link will write (the old
  // tile's pointer word; the parent's child-table or skip word) with their dirty bytes and
  // the records their tags read, and the parent's record (the one its buckets name).
  // Loads only; a word another change moves meanwhile is found again when applied.
  void prefetch_words(const Change& c) const {
    auto word = [&](uint32_t w) {
      __builtin_prefetch(&page_shadow[w]);
      __builtin_prefetch(&dirty[w / kDirtyBlockWords / 64]);
      if (w >= off_children && w < off_pcf) __builtin_prefetch(&slot_recs[(w - off_children) / L::kChildTableWords]);
    };
    if (c.old_tile != kInvalidTile) {
      const uint64_t tag = slot_recs[c.slot].pointer;
      if (tag != ~uint64_t(0) && uint32_t(tag) < page_shadow.size()) word(uint32_t(tag));
    }
    if (!c.link || sg) return;
    const uint32_t level = tile_level(c.tile);
    if (level < k) return;
    const uint64_t morton = tile_morton(c.tile);
    if (level == k) {
      word(off_skip_slots + uint32_t((uint64_t(morton_compact(morton >> 1)) << k) + morton_compact(morton)));
      return;
    }
    const uint32_t p = tile_slot.guess(tile_parent(c.tile, 1));
    if (p >= slot_count) return;
    __builtin_prefetch(&slot_recs[p]);
    const uint64_t low = tile_child_morton(c.tile, 1);
    word(off_children + p * L::kChildTableWords + (morton_compact(low >> 1) << 1) + morton_compact(low));
  }
  void queue_change(const Change& c) {
    if (changes_count == kChangeLag) apply_oldest_change();
    changes[(changes_head + changes_count++) % kChangeLag] = c;
    prefetch_change(c);
    if (changes_count > kChangeLag / 2) prefetch_words(changes[(changes_head + changes_count - 1 - kChangeLag / 2) % kChangeLag]);
  }
  // One copy region more, or the last one longer when both ranges continue it (adjacent
  // dirty page-table blocks; a tile that fills its slot next to the last): fewer regions
  // for the driver to record and the device to run, the same bytes.
  static void add_copy(std::vector<VkBufferCopy>& copies, uint64_t src, uint64_t dst, uint64_t bytes) {
    if (!copies.empty()) {
      VkBufferCopy& last = copies.back();
      if (last.srcOffset + last.size == src && last.dstOffset + last.size == dst) {
        last.size += bytes;
        return;
      }
    }
    copies.push_back({src, dst, bytes});
  }

  // Compares every slot with the cache and stages what changed into `f`'s staging
  // buffer (tile bytes within the budget, then the dirty page-table blocks).
  void stage_changes(Frame& f, FrameStats& fs) {
    pool_copies.clear();
    page_copies.clear();
    uint64_t off = 0;
    auto* staging = static_cast<uint8_t*>(f.staging.mapped);
    // The cache's changed slots (client::CacheView), in slot order; mirror_tile is the
    // view's `known`: a slot left for a later frame (budget) stays unlinked until then.
    // The mirror's updates (unlink, link) are queued and applied kChangeLag changes later,
    // in the same order; mirror_tile[s] may show a queued change's tile meanwhile (the view
    // writes it), which nothing before its link reads: unlink gets the old tile with it.
    view->changed_slots(mirror_tile, [&](const client::SlotChange& sc) {
      const uint32_t s = sc.slot;
      Change c;
      c.slot = s;
      c.old_tile = mirror_tile[s];
      bool done = true;
      if (sc.tile != client::kNoTile) {
        const uint32_t bytes = align4(uint32_t(sc.bytes.size()));
        if (off > 0 && off + bytes > opt.upload_budget_bytes) {  // one slot always fits: no starvation
          ++totals.slots_deferred;
          done = false;
        } else {
          std::memcpy(staging + off, sc.bytes.data(), sc.bytes.size());
          std::memset(staging + off + sc.bytes.size(), 0, bytes - sc.bytes.size());
          const uint64_t dst = uint64_t(s) * slot_words * 4;
          if (bytes) add_copy(pool_copies, off, dst, bytes);
          off += bytes;
          c.link = true;
          c.tile = sc.tile;
          read_index_entries(c, sc.bytes);
          ++fs.slots_uploaded;
        }
      }
      if (c.old_tile != kInvalidTile || c.link) queue_change(c);
      return done;
    });
    while (changes_count > 0) apply_oldest_change();
    fs.tile_bytes = off;
    if (deep_part) deep.update(*view, [this](uint32_t w, uint32_t v) { set_page_word(w, v); });
    if (engine && !page_table_sent) {  // engine mode's first frame: the whole page table
      std::memcpy(staging + off, page_shadow.data(), page_shadow.size() * 4);
      page_copies.push_back({off, 0, page_shadow.size() * 4});
      off += page_shadow.size() * 4;
      totals.page_words_uploaded += page_shadow.size();
      const VkBufferCopy dict = stage_dictionary(f, off);  // into the pool after the first frame's fill
      if (dict.size) pool_copies.push_back(dict);
      off += dict.size;
      for (uint32_t blk : dirty_list) dirty[blk / 64] = 0;
      dirty_list.clear();
      page_table_sent = true;
    }
    std::sort(dirty_list.begin(), dirty_list.end());
    for (uint32_t blk : dirty_list) {
      const uint32_t w0 = blk * kDirtyBlockWords;
      const uint32_t n = std::min<uint32_t>(kDirtyBlockWords, uint32_t(page_shadow.size()) - w0);
      std::memcpy(staging + off, page_shadow.data() + w0, n * 4);
      add_copy(page_copies, off, uint64_t(w0) * 4, uint64_t(n) * 4);
      off += n * 4;
      dirty[blk / 64] = 0;
      totals.page_words_uploaded += n;
    }
    dirty_list.clear();
    fs.bytes_uploaded = off;
    fs.page_bytes = off - fs.tile_bytes;
    totals.tile_bytes += fs.tile_bytes;
    totals.page_bytes += fs.page_bytes;
    totals.slots_uploaded += fs.slots_uploaded;
    totals.bytes_uploaded += off;
  }


  // ---- engine mode ----
  // The slot pool and the page table; with GpuOptions::texel_buffers also uniform texel
  // buffers, each with an R32_UINT view (shadowtile.glsl's ST_TEXEL_BUFFERS reads).
  void create_pool_and_page() {
    const uint64_t page_words = page_shadow.size();
    if (opt.texel_buffers) {
      const uint64_t elements = ctx->properties().limits.maxTexelBufferElements;
      for (auto [what, words] : {std::pair{"slot pool", pool_bytes / 4}, std::pair{"page table", page_words}})
        if (words > elements)
          throw GpuError(std::string("GpuMap: texel_buffers: the ") + what + " (" + std::to_string(words) +
                         " words) exceeds device '" + ctx->device_name() + "' maxTexelBufferElements (" +
                         std::to_string(elements) + "); use fewer cache slots, or storage buffers");
    }
    const VkBufferUsageFlags texel = opt.texel_buffers ? VK_BUFFER_USAGE_UNIFORM_TEXEL_BUFFER_BIT : 0;
    pool = ctx->make_buffer(pool_bytes, false, texel);
    page = ctx->make_buffer(page_words * 4, false, texel);
    if (!opt.texel_buffers) return;
    for (auto [b, v] : {std::pair{&pool, &pool_view}, std::pair{&page, &page_view}}) {
      VkBufferViewCreateInfo vci{};
      vci.sType = VK_STRUCTURE_TYPE_BUFFER_VIEW_CREATE_INFO;
      vci.buffer = b->buffer;
      vci.format = VK_FORMAT_R32_UINT;  // uniform texel buffers: a mandatory format feature
      vci.offset = 0;
      vci.range = VK_WHOLE_SIZE;
      vk_check(ctx->vk.CreateBufferView(ctx->device(), &vci, ctx->callbacks(), v), "vkCreateBufferView");
    }
  }

  void create_engine_objects() {
    const VkFunctions& vk = ctx->vk;
    VkDevice d = ctx->device();
    const VkAllocationCallbacks* cb = ctx->callbacks();
    const uint64_t range = ctx->properties().limits.maxStorageBufferRange;
    if (page_shadow.size() * 4 > range)
      throw GpuError("GpuMap: the page table (" + std::to_string(page_shadow.size() * 4) +
                     " bytes) exceeds device '" + ctx->device_name() + "' maxStorageBufferRange");
    {
      uint32_t qn = 0;
      vk.GetPhysicalDeviceQueueFamilyProperties(ctx->physical(), &qn, nullptr);
      std::vector<VkQueueFamilyProperties> qs(qn);
      vk.GetPhysicalDeviceQueueFamilyProperties(ctx->physical(), &qn, qs.data());
      if (qs[ctx->queue_family()].queueFlags & VK_QUEUE_GRAPHICS_BIT)
        shader_stages |= VK_PIPELINE_STAGE_VERTEX_SHADER_BIT | VK_PIPELINE_STAGE_FRAGMENT_SHADER_BIT;
    }
    create_pool_and_page();
    const uint64_t staging =
        opt.upload_budget_bytes + uint64_t(slot_words) * 4 + page_shadow.size() * 4 + uint64_t(dict_words) * 4;
    const uint64_t fb_bytes = (L::kFbHeaderWords + uint64_t(opt.feedback_capacity) * (2 + L::kFbRecordWords)) * 4;
    retired.reserve(opt.frames_in_flight);
    frames.resize(opt.frames_in_flight);
    for (Frame& f : frames) {
      f.staging = ctx->make_buffer(staging, true, 0, BufferUse::upload);
      // Written once here, so no frame's staging pays the first touch of its pages (a
      // driver whose host-visible memory is ordinary pageable memory, as lavapipe's, would
      // take those page faults inside record_uploads).
      std::memset(f.staging.mapped, 0, staging);
      f.feedback = ctx->make_buffer(fb_bytes, true, 0, BufferUse::readback);
      // Empty, its capacity written, once: later frames' collect_feedback clears what each
      // frame claimed on the host (no fill of the buffer over the bus each frame).
      std::memset(f.feedback.mapped, 0, fb_bytes);
      static_cast<uint32_t*>(f.feedback.mapped)[L::kFbCapacity] = opt.feedback_capacity;
    }
    // The pass: pool, page table, feedback, positions, normals (texelFetch through our
    // immutable nearest sampler), visibility (R32F storage image).
    VkSamplerCreateInfo sci{};
    sci.sType = VK_STRUCTURE_TYPE_SAMPLER_CREATE_INFO;
    sci.magFilter = sci.minFilter = VK_FILTER_NEAREST;
    sci.mipmapMode = VK_SAMPLER_MIPMAP_MODE_NEAREST;
    sci.addressModeU = sci.addressModeV = sci.addressModeW = VK_SAMPLER_ADDRESS_MODE_CLAMP_TO_EDGE;
    vk_check(vk.CreateSampler(d, &sci, cb, &ep_sampler), "vkCreateSampler");
    // Binding 6: the light image, read only by the ST_PASS_LIGHT pipeline.
    const auto setup = ctx->setup();
    auto b = vk_setup::bindings(7, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, VK_SHADER_STAGE_COMPUTE_BIT);
    for (uint32_t i = 3; i < 7; ++i)
      b[i].descriptorType = i < 5 ? VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER : VK_DESCRIPTOR_TYPE_STORAGE_IMAGE;
    b[3].pImmutableSamplers = b[4].pImmutableSamplers = &ep_sampler;
    ep_set_layout = vk_setup::set_layout(setup, b);
    ep_layout = vk_setup::pipeline_layout(setup, {&ep_set_layout, 1}, {VK_SHADER_STAGE_COMPUTE_BIT, 0, L::kPcWords * 4});
    const uint32_t n = opt.frames_in_flight;
    const VkDescriptorPoolSize ps[3] = {{VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 3 * n},
                                        {VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER, 2 * n},
                                        {VK_DESCRIPTOR_TYPE_STORAGE_IMAGE, 2 * n}};
    ep_pool = vk_setup::descriptor_pool(setup, n, ps);
    for (Frame& f : frames) f.set = vk_setup::allocate_set(setup, ep_pool, ep_set_layout);
    // Specialization constant 0 (shadowtile.glsl's ST_MAP_KIND_ID): 1 a 2D map, 2 a stack map;
    // the other kind's tile walk is left out of the pipeline.
    const uint32_t map_kind = sg ? 2u : 1u;
    const VkSpecializationMapEntry entry{0, 0, sizeof(uint32_t)};
    const VkSpecializationInfo spec{1, &entry, sizeof(map_kind), &map_kind};
    ep_pipeline = vk_setup::compute_pipeline(setup, ep_layout, engine_shadow_pass_spirv(false), &spec);
    if (opt.light_pass)
      ep_light_pipeline = vk_setup::compute_pipeline(setup, ep_layout, engine_shadow_pass_spirv(true), &spec);
  }

  void need_engine(const char* call) const {
    if (!engine) throw GpuError(std::string("GpuMap::") + call + ": only in engine mode (GpuMap(map, EngineDevice, options))");
  }
  void need_own(const char* call) const {
    if (engine)
      throw GpuError(std::string("GpuMap::") + call +
                     ": not in engine mode (record_uploads / record_shadow_pass into the engine's command buffers)");
  }

  // The ring slot recording `frame` now (the last record_uploads), or a GpuError.
  Frame& current(uint64_t frame, const char* call) {
    Frame& f = frames[frame % frames.size()];
    if (!any_recorded || frame != last_recorded || !f.in_flight || f.frame != frame)
      throw GpuError(std::string("GpuMap::") + call + ": frame " + std::to_string(frame) +
                     " is not the frame being recorded (record_uploads(cmd, frame) first)");
    return f;
  }

  void barrier(VkCommandBuffer cmd, VkPipelineStageFlags src, VkAccessFlags src_access, VkPipelineStageFlags dst,
               VkAccessFlags dst_access) const {
    VkMemoryBarrier mb{};
    mb.sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER;
    mb.srcAccessMask = src_access;
    mb.dstAccessMask = dst_access;
    ctx->vk.CmdPipelineBarrier(cmd, src, dst, 0, 1, &mb, 0, nullptr, 0, nullptr);
  }

  // The copies in calls of at most kRegionsPerCall regions. Mesa's common command queue
  // (lavapipe's) copies a call's regions into one allocation of 40 bytes a region (and
  // converts them through another past 8): past about 1 KiB that is a large-bin malloc,
  // which took 30-40 us in a quarter of bench_frame_path's frames (100 tiles, 100 regions,
  // cold caches: its p90). 25 regions (1000 bytes) stay within the sizes glibc's
  // per-thread cache serves, and each call costs the queue allocations of its own besides:
  // 4 calls of 25 recorded 100 tiles in about half the time of 13 calls of 8
  // (bench_frame_path, lavapipe).
  void record_copies(VkCommandBuffer cmd, VkBuffer src, VkBuffer dst, const std::vector<VkBufferCopy>& copies) const {
    for (size_t i = 0; i < copies.size(); i += kRegionsPerCall)
      ctx->vk.CmdCopyBuffer(cmd, src, dst, uint32_t(std::min<size_t>(kRegionsPerCall, copies.size() - i)), copies.data() + i);
  }

  FrameStats record_uploads(VkCommandBuffer cmd, uint64_t frame) {
    need_engine("record_uploads");
    if (any_recorded && frame <= last_recorded)
      throw GpuError("GpuMap::record_uploads: frame " + std::to_string(frame) + " is not after the last frame recorded (" +
                     std::to_string(last_recorded) + ")");
    Frame& f = frames[frame % frames.size()];
    if (f.in_flight)
      throw GpuError("GpuMap::record_uploads: frame " + std::to_string(frame) + "'s ring slot still holds frame " +
                     std::to_string(f.frame) + ", not retired (retire(" + std::to_string(f.frame) +
                     ") once it completes, or more frames_in_flight)");
    const VkFunctions& vk = ctx->vk;
    FrameStats fs;
    fs.frame = frame;
    const bool first = !page_table_sent;
    stage_changes(f, fs);
    // Earlier frames' shader reads of the pool and page table end before the copies write.
    barrier(cmd, shader_stages, VK_ACCESS_SHADER_READ_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT);
    if (first) {  // the pool starts zeroed (as the own-device mode's), before any slot lands
      vk.CmdFillBuffer(cmd, pool.buffer, 0, VK_WHOLE_SIZE, 0);
      barrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT,
              VK_ACCESS_TRANSFER_WRITE_BIT);
    }
    record_copies(cmd, f.staging.buffer, pool.buffer, pool_copies);
    record_copies(cmd, f.staging.buffer, page.buffer, page_copies);
    // The frame's feedback set is empty already: collect_feedback cleared it on the host
    // when the frame that last used the ring slot retired (host-coherent memory, written
    // before the engine submits this frame).
    barrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT, shader_stages,
            VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT);
    f.in_flight = true;
    f.collected = false;
    f.pass_recorded = false;
    f.frame = frame;
    f.stats = fs;
    any_recorded = true;
    last_recorded = frame;
    ++totals.frames;
    return fs;
  }

  void record_shadow_pass(VkCommandBuffer cmd, uint64_t frame, const ShadowPassImages& im, const ShadowPassSettings& in) {
    need_engine("record_shadow_pass");
    Frame& f = current(frame, "record_shadow_pass");
    if (f.pass_recorded)
      throw GpuError("GpuMap::record_shadow_pass: one pass per frame (frame " + std::to_string(frame) + " has one)");
    if (!im.positions || !im.normals || !im.visibility || im.width == 0 || im.height == 0)
      throw GpuError("GpuMap::record_shadow_pass: positions, normals, visibility and a non-empty size are needed");
    check_kernel("GpuMap::record_shadow_pass", in.kernel);
    if (!sg && in.soft) throw GpuError("GpuMap::record_shadow_pass: a soft pass needs a stack map (a pack built with a light set)");
    if (!sg && page_shadow[L::kPtLight] == 0) (void)map_light();  // throws: the light the pass refuses
    if (im.light && !ep_light_pipeline)
      throw GpuError("GpuMap::record_shadow_pass: a light image needs GpuOptions::light_pass (its pipeline)");
    const VkFunctions& vk = ctx->vk;
    const VkDescriptorBufferInfo bufs[3] = {{pool.buffer, 0, VK_WHOLE_SIZE}, {page.buffer, 0, VK_WHOLE_SIZE},
                                            {f.feedback.buffer, 0, VK_WHOLE_SIZE}};
    const VkDescriptorImageInfo imgs[4] = {{VK_NULL_HANDLE, im.positions, im.gbuffer_layout},
                                           {VK_NULL_HANDLE, im.normals, im.gbuffer_layout},
                                           {VK_NULL_HANDLE, im.visibility, VK_IMAGE_LAYOUT_GENERAL},
                                           {VK_NULL_HANDLE, im.light, VK_IMAGE_LAYOUT_GENERAL}};
    const uint32_t writes = im.light ? 7 : 6;
    VkWriteDescriptorSet w[7] = {};
    for (uint32_t i = 0; i < writes; ++i) {
      w[i].sType = VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET;
      w[i].dstSet = f.set;
      w[i].dstBinding = i;
      w[i].descriptorCount = 1;
      w[i].descriptorType = i < 3 ? VK_DESCRIPTOR_TYPE_STORAGE_BUFFER
                            : i < 5 ? VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER
                                    : VK_DESCRIPTOR_TYPE_STORAGE_IMAGE;
      if (i < 3) w[i].pBufferInfo = &bufs[i];
      else w[i].pImageInfo = &imgs[i - 3];
    }
    vk.UpdateDescriptorSets(ctx->device(), writes, w, 0, nullptr);
    uint32_t pc[L::kPcWords] = {};
    pc[L::kPcCount] = im.width;
    pc[L::kPcHeight] = im.height;
    pc[L::kPcKernel] = in.kernel;
    pc[L::kPcFlags] = (in.neighbour_footprint ? L::kFlagNeighbourFootprint : 0) | (in.soft ? L::kFlagSoft : 0) |
                      (in.resume_walks ? L::kFlagResumeWalks : 0) | (in.receiver_plane ? L::kFlagReceiverPlane : 0);
    if (sg) {
      const StackTime t = in.soft ? StackTime{} : stack_time(sg->slices, in.time);
      pc[L::kPcSliceA] = t.a;
      pc[L::kPcSliceB] = t.b;
      pc[L::kPcTimeWeight] = std::bit_cast<uint32_t>(t.f);
    }
    pc[L::kPcNormalOffset] = std::bit_cast<uint32_t>(in.normal_offset);
    pc[L::kPcFootprint] = std::bit_cast<uint32_t>(in.footprint);
    vk.CmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, im.light ? ep_light_pipeline : ep_pipeline);
    vk.CmdBindDescriptorSets(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, ep_layout, 0, 1, &f.set, 0, nullptr);
    vk.CmdPushConstants(cmd, ep_layout, VK_SHADER_STAGE_COMPUTE_BIT, 0, sizeof(pc), pc);
    vk.CmdDispatch(cmd, (im.width + 7) / 8, (im.height + 7) / 8, 1);
    f.pass_recorded = true;
  }

  void record_end_of_frame(VkCommandBuffer cmd, uint64_t frame) {
    need_engine("record_end_of_frame");
    current(frame, "record_end_of_frame");
    barrier(cmd, shader_stages, VK_ACCESS_SHADER_WRITE_BIT, VK_PIPELINE_STAGE_HOST_BIT, VK_ACCESS_HOST_READ_BIT);
  }

  std::span<const FrameStats> retire(uint64_t completed) {
    need_engine("retire");
    retired.clear();
    for (;;) {  // oldest first; at most frames_in_flight slots
      Frame* next = nullptr;
      for (Frame& f : frames)
        if (f.in_flight && f.frame <= completed && (!next || f.frame < next->frame)) next = &f;
      if (!next) break;
      next->in_flight = false;
      collect_feedback(*next);
      retired.push_back(next->stats);
    }
    return retired;
  }

  // ---- frames (own-device mode) ----
  // One evaluate batch: `words` input words per query, written by fill(query, words).
  template <class Query, class Fill>
  uint64_t submit_queries(std::span<const Query> queries, uint32_t words, Kernel kernel, Fill fill,
                          uint32_t out_words = 1) {
    if (queries.size() > opt.max_queries)
      throw GpuError("GpuMap::evaluate: " + std::to_string(queries.size()) + " queries, more than max_queries (" +
                     std::to_string(opt.max_queries) + ")");
    Frame& f = acquire();
    auto* in = static_cast<uint32_t*>(f.input_host.mapped);
    f.input_bytes = queries.size() * words * 4;
    f.normals_bytes = 0;
    for (size_t i = 0; i < queries.size(); ++i) fill(queries[i], in + i * words);
    uint32_t pc[L::kPcWords] = {};
    pc[L::kPcCount] = uint32_t(queries.size());
    f.out_words = out_words;
    return submit(f, kernel, uint32_t(queries.size()), pc);
  }

  Frame& acquire() {
    Frame& f = frames[next_frame % frames.size()];
    if (f.in_flight) finish(f);
    f.out_words = 1;
    return f;
  }

  void finish(Frame& f) {
    vk_check(ctx->vk.WaitForFences(ctx->device(), 1, &f.fence, VK_TRUE, UINT64_MAX), "vkWaitForFences");
    vk_check(ctx->vk.ResetFences(ctx->device(), 1, &f.fence), "vkResetFences");
    f.in_flight = false;
    if (!f.collected) collect_feedback(f);
  }

  void collect_feedback(Frame& f) {
    f.collected = true;
    const auto* fb = static_cast<const uint32_t*>(f.feedback.mapped);
    FrameStats& fs = f.stats;
    fs.holes = fb[L::kFbHoles];
    fs.absent_taps = fb[L::kFbAbsentTaps];
    fs.feedback_dropped = fb[L::kFbDropped];
    wanted.clear();
    deep_wanted.clear();
    feedback.clear();
    const uint32_t cap = opt.feedback_capacity;
    // The keys this frame claimed, listed in claim order (st_feedback): a frame that
    // claimed none (every tile it read was resident) reads the header alone.
    auto* fbw = static_cast<uint32_t*>(f.feedback.mapped);
    const uint32_t claimed = std::min(fb[L::kFbUsed], cap);
    const uint32_t* list = fb + L::kFbHeaderWords + size_t(cap) * (1 + L::kFbRecordWords);
    for (uint32_t i = 0; i < claimed; ++i) {
      const uint32_t h = list[i] & (cap - 1);
      const uint32_t key = fb[L::kFbHeaderWords + h];
      uint32_t* rec = fbw + L::kFbHeaderWords + cap + size_t(h) * L::kFbRecordWords;
      const uint32_t level = rec[L::kFbRecLevel], x = rec[L::kFbRecX], y = rec[L::kFbRecY];
      const uint32_t value_bits = rec[L::kFbRecValue], kind_word = rec[L::kFbRecKind], count = rec[L::kFbRecCount];
      // Cleared for the ring slot's next frame, here on the host: nothing else to empty.
      fbw[L::kFbHeaderWords + h] = 0;
      std::fill(rec, rec + L::kFbRecordWords, 0u);
      if (key == 0) continue;
      if (deep_part && (key & (L::kFbChildKeyBit | L::kFbDeepKeyBit)) == L::kFbDeepKeyBit) {
        // An absent deep tile (st_deep.glsl): asked of the Map's deep part, not its cache.
        const client::DeepWant dw{x, y};
        if (level != deep.level() || (key & ~L::kFbDeepKeyBit) != deep.key(dw.tx, dw.ty)) continue;
        deep_wanted.push_back(dw);
        feedback.push_back({deep.tile_id(dw.tx, dw.ty), count});
        continue;
      }
      client::WantedTile w;
      if (sg) {  // an absent stack cell: kFbStackKeyBit | cell
        const uint32_t cell = key & ~L::kFbStackKeyBit;
        if ((key & L::kFbChildKeyBit) || !(key & L::kFbStackKeyBit) || cell >= sg->cells.size()) continue;
        w.tile = view->stack_cell_tile(cell);
      } else {
        if (level > map_level || (x >> level) != 0 || (y >> level) != 0) continue;
        w.tile = make_tile_id(level, x, y);
      }
      w.entry.value = std::bit_cast<float>(value_bits);
      w.entry.kind = kind_word & 0xFFu;
      w.entry.index_levels = (kind_word >> 8) & 0xFFu;
      w.priority = uint16_t(std::clamp<uint32_t>(count, 1, 65535));
      wanted.push_back(w);
      feedback.push_back({w.tile, count});
    }
    fbw[L::kFbUsed] = fbw[L::kFbDropped] = fbw[L::kFbHoles] = fbw[L::kFbAbsentTaps] = 0;
    fs.feedback_tiles = uint32_t(wanted.size() + deep_wanted.size());
    fs.deep_wanted = uint32_t(deep_wanted.size());
    // What the feedback moved: its header and, per claimed key, its list entry, key and record.
    fs.feedback_bytes = (uint64_t(L::kFbHeaderWords) + uint64_t(claimed) * (2 + L::kFbRecordWords)) * 4;
    totals.feedback_bytes += fs.feedback_bytes;
    fs.requested = uint32_t(view->want_tiles(wanted));
    if (!deep_wanted.empty()) fs.requested += uint32_t(view->want_deep_tiles(deep_wanted));
    if (queries && !engine) {
      uint64_t ts[2] = {0, 0};
      const uint32_t q = uint32_t(&f - frames.data()) * 2;
      if (ctx->vk.GetQueryPoolResults(ctx->device(), queries, q, 2, sizeof(ts), ts, 8, VK_QUERY_RESULT_64_BIT) == VK_SUCCESS) {
        const uint32_t bits = ctx->timestamp_bits();
        const uint64_t mask = bits >= 64 ? ~uint64_t(0) : (uint64_t(1) << bits) - 1;
        fs.gpu_ms = double((ts[1] - ts[0]) & mask) * ctx->properties().limits.timestampPeriod * 1e-6;
      }
    }
    totals.feedback_tiles += fs.feedback_tiles;
    totals.feedback_requested += fs.requested;
    totals.feedback_dropped += fs.feedback_dropped;
    totals.holes += fs.holes;
  }

  uint64_t submit(Frame& f, Kernel which, uint32_t invocations, const uint32_t (&pc)[L::kPcWords]) {
    FrameStats fs;
    auto* fb = static_cast<uint32_t*>(f.feedback.mapped);
    std::memset(fb, 0, f.feedback.size);
    fb[L::kFbCapacity] = opt.feedback_capacity;
    stage_changes(f, fs);
    VkCommandBuffer cmd = f.cmd;
    vk_check(ctx->vk.ResetCommandBuffer(cmd, 0), "vkResetCommandBuffer");
    VkCommandBufferBeginInfo bi{};
    bi.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO;
    bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
    vk_check(ctx->vk.BeginCommandBuffer(cmd, &bi), "vkBeginCommandBuffer");
    const uint32_t q = uint32_t(&f - frames.data()) * 2;
    if (queries) ctx->vk.CmdResetQueryPool(cmd, queries, q, 2);
    if (!pool_copies.empty() || !page_copies.empty() || f.input_bytes || f.normals_bytes) {
      // Every earlier dispatch (of any frame) has finished reading before a copy writes.
      VkMemoryBarrier war{};
      war.sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER;
      war.srcAccessMask = VK_ACCESS_SHADER_READ_BIT;
      war.dstAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
      ctx->vk.CmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT, 0, 1, &war, 0,
                           nullptr, 0, nullptr);
      record_copies(cmd, f.staging.buffer, pool.buffer, pool_copies);
      record_copies(cmd, f.staging.buffer, page.buffer, page_copies);
      const VkBufferCopy in_copy{0, 0, f.input_bytes}, n_copy{0, 0, f.normals_bytes};
      if (f.input_bytes) ctx->vk.CmdCopyBuffer(cmd, f.input_host.buffer, f.input.buffer, 1, &in_copy);
      if (f.normals_bytes) ctx->vk.CmdCopyBuffer(cmd, f.normals_host.buffer, f.normals.buffer, 1, &n_copy);
    }
    // Copies (this frame's and the first upload's) land before the dispatch reads.
    VkMemoryBarrier raw{};
    raw.sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER;
    raw.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT | VK_ACCESS_HOST_WRITE_BIT;
    raw.dstAccessMask = VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT;
    ctx->vk.CmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT | VK_PIPELINE_STAGE_HOST_BIT,
                         VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, 0, 1, &raw, 0, nullptr, 0, nullptr);
    kernels.record(cmd, which, f.set, pc);
    if (queries) ctx->vk.CmdWriteTimestamp(cmd, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, queries, q);
    ctx->vk.CmdDispatch(cmd, (invocations + L::kWorkgroupSize - 1) / L::kWorkgroupSize, 1, 1);
    if (queries) ctx->vk.CmdWriteTimestamp(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, queries, q + 1);
    VkMemoryBarrier out{};
    out.sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER;
    out.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT;
    out.dstAccessMask = VK_ACCESS_TRANSFER_READ_BIT | VK_ACCESS_HOST_READ_BIT;
    ctx->vk.CmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
                         VK_PIPELINE_STAGE_TRANSFER_BIT | VK_PIPELINE_STAGE_HOST_BIT, 0, 1, &out, 0, nullptr, 0, nullptr);
    if (invocations) {
      const VkBufferCopy out_copy{0, 0, uint64_t(invocations) * 4 * f.out_words};
      ctx->vk.CmdCopyBuffer(cmd, f.output.buffer, f.output_host.buffer, 1, &out_copy);
      VkMemoryBarrier host{};
      host.sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER;
      host.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
      host.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
      ctx->vk.CmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_HOST_BIT, 0, 1, &host, 0, nullptr, 0,
                           nullptr);
    }
    vk_check(ctx->vk.EndCommandBuffer(cmd), "vkEndCommandBuffer");
    VkSubmitInfo si{};
    si.sType = VK_STRUCTURE_TYPE_SUBMIT_INFO;
    si.commandBufferCount = 1;
    si.pCommandBuffers = &cmd;
    vk_check(ctx->vk.QueueSubmit(ctx->queue(), 1, &si, f.fence), "vkQueueSubmit");
    f.in_flight = true;
    f.collected = false;
    f.frame = next_frame++;
    f.count = invocations;
    fs.frame = f.frame;
    fs.host_io_bytes = f.input_bytes + f.normals_bytes + uint64_t(invocations) * 4 * f.out_words;  // in, answers back
    totals.host_io_bytes += fs.host_io_bytes;
    f.stats = fs;
    ++totals.frames;
    return f.frame;
  }

  Frame* find(uint64_t frame) {
    for (Frame& f : frames)
      if (f.frame == frame && (f.in_flight || !f.collected)) return &f;
    return nullptr;
  }
};

GpuMap::GpuMap(client::Map map, GpuOptions options)
    : impl_(std::make_unique<Impl>(std::move(map), nullptr, std::move(options))) {}
GpuMap::GpuMap(client::Map map, const EngineDevice& device, GpuOptions options)
    : impl_(std::make_unique<Impl>(std::move(map), &device, std::move(options))) {}
GpuMap::~GpuMap() = default;

uint32_t GpuMap::max_cache_slots(uint64_t storage_range, uint32_t slot_bytes, uint64_t dictionary_bytes) {
  const uint64_t slot = align16(std::max<uint32_t>(slot_bytes, 1));  // as Impl's pool_bytes
  const uint64_t dict = (dictionary_bytes + 15) / 16 * 16;             // whole quads after the slots
  const uint64_t room = storage_range > dict ? storage_range - dict : 0;
  return uint32_t(std::min<uint64_t>(room / slot, uint64_t(1) << 23));
}
// The pool's byte range on a device: its storage-buffer range, and with texel buffers
// also its texel-buffer range (R32_UINT texels).
namespace {
uint64_t pool_range(const VkPhysicalDeviceLimits& l, bool texel_buffers) {
  const uint64_t storage = l.maxStorageBufferRange;
  return texel_buffers ? std::min<uint64_t>(storage, uint64_t(l.maxTexelBufferElements) * 4) : storage;
}
}  // namespace
uint32_t GpuMap::max_cache_slots(const EngineDevice& device, uint32_t slot_bytes, bool texel_buffers,
                                 uint64_t dictionary_bytes) {
  const VkContext ctx(device);
  return max_cache_slots(pool_range(ctx.properties().limits, texel_buffers), slot_bytes, dictionary_bytes);
}
uint32_t GpuMap::max_cache_slots(const GpuOptions& options, uint32_t slot_bytes, uint64_t dictionary_bytes) {
  const VkContext ctx(options.device, false);
  return max_cache_slots(pool_range(ctx.properties().limits, options.texel_buffers), slot_bytes, dictionary_bytes);
}

std::span<const FrameStats> GpuMap::retire(uint64_t completed_frame) { return impl_->retire(completed_frame); }

FrameStats GpuMap::record_uploads(VkCommandBuffer cmd, uint64_t frame) { return impl_->record_uploads(cmd, frame); }

void GpuMap::record_shadow_pass(VkCommandBuffer cmd, uint64_t frame, const ShadowPassImages& images,
                                const ShadowPassSettings& settings) {
  impl_->record_shadow_pass(cmd, frame, images, settings);
}

void GpuMap::record_end_of_frame(VkCommandBuffer cmd, uint64_t frame) { impl_->record_end_of_frame(cmd, frame); }

GpuDescriptors GpuMap::descriptors(uint64_t frame) const {
  const Impl& m = *impl_;
  m.need_engine("descriptors");
  const Impl::Frame& f = m.frames[frame % m.frames.size()];
  GpuDescriptors d;
  d.pool = {m.pool.buffer, 0, VK_WHOLE_SIZE};
  d.page_table = {m.page.buffer, 0, VK_WHOLE_SIZE};
  d.feedback = {f.feedback.buffer, 0, VK_WHOLE_SIZE};
  d.pool_view = m.pool_view;
  d.page_table_view = m.page_view;
  return d;
}

bool GpuMap::engine_mode() const { return impl_->engine; }

FrameStats GpuMap::evaluate(std::span<const GpuQuery> queries, std::span<float> out) {
  if (queries.size() != out.size()) throw GpuError("GpuMap::evaluate: queries and out differ in size");
  return wait(submit_evaluate(queries), out);
}

uint64_t GpuMap::submit_evaluate(std::span<const GpuQuery> queries) {
  impl_->need_own("submit_evaluate");
  check_query_kernels(queries);
  return impl_->submit_queries(queries, L::kQueryWords, Kernel::evaluate, [](const GpuQuery& q, uint32_t* w) {
    w[L::kQueryX] = q.x;
    w[L::kQueryY] = q.y;
    w[L::kQueryReceiver] = std::bit_cast<uint32_t>(q.receiver);
    w[L::kQueryFootprint] = std::bit_cast<uint32_t>(q.footprint);
    w[L::kQueryR] = q.r;
    w[L::kQueryLevel] = q.level;
  });
}

FrameStats GpuMap::evaluate(std::span<const GpuStackQuery> queries, std::span<float> out) {
  if (queries.size() != out.size()) throw GpuError("GpuMap::evaluate: queries and out differ in size");
  return wait(submit_evaluate(queries), out);
}

uint64_t GpuMap::submit_evaluate(std::span<const GpuStackQuery> queries) {
  impl_->need_own("submit_evaluate");
  if (!impl_->sg) throw GpuError("GpuMap::evaluate: stack queries on a map that is not a stack");
  check_query_kernels(queries);
  return impl_->submit_queries(queries, L::kSqWords, Kernel::stack_evaluate, [](const GpuStackQuery& q, uint32_t* w) {
    w[L::kSqX] = q.x;
    w[L::kSqY] = q.y;
    w[L::kSqSlice] = q.slice;
    w[L::kSqLevel] = q.level;
    w[L::kSqReceiver] = std::bit_cast<uint32_t>(q.receiver);
    w[L::kSqFootprint] = std::bit_cast<uint32_t>(q.footprint);
    w[L::kSqR] = q.r;
  });
}

uint64_t GpuMap::submit_shadow_pass(const ShadowPassInput& in) {
  Impl& m = *impl_;
  m.need_own("submit_shadow_pass");
  const uint64_t pixels = uint64_t(in.width) * in.height;
  if (pixels == 0 || pixels > m.opt.max_pixels)
    throw GpuError("GpuMap::submit_shadow_pass: " + std::to_string(in.width) + "x" + std::to_string(in.height) +
                   " pixels, want 1.." + std::to_string(m.opt.max_pixels));
  if (in.positions.size() != pixels * 4 || in.normals.size() != pixels * 4)
    throw GpuError("GpuMap::submit_shadow_pass: positions and normals need 4 floats per pixel");
  check_kernel("GpuMap::submit_shadow_pass", in.kernel);
  if (m.sg) {
    const StackTime t = in.soft ? StackTime{} : stack_time(m.sg->slices, in.time);
    Impl::Frame& f = m.acquire();
    std::memcpy(f.input_host.mapped, in.positions.data(), pixels * 16);
    std::memcpy(f.normals_host.mapped, in.normals.data(), pixels * 16);
    f.input_bytes = f.normals_bytes = pixels * 16;
    uint32_t pc[L::kPcWords] = {};
    pc[L::kPcCount] = in.width;
    pc[L::kPcHeight] = in.height;
    pc[L::kPcKernel] = in.kernel;
    pc[L::kPcFlags] = (in.neighbour_footprint ? L::kFlagNeighbourFootprint : 0) | (in.soft ? L::kFlagSoft : 0) |
                      (in.resume_walks ? L::kFlagResumeWalks : 0) | (in.receiver_plane ? L::kFlagReceiverPlane : 0);
    pc[L::kPcSliceA] = t.a;
    pc[L::kPcSliceB] = t.b;
    pc[L::kPcTimeWeight] = std::bit_cast<uint32_t>(t.f);
    pc[L::kPcNormalOffset] = std::bit_cast<uint32_t>(in.normal_offset);
    pc[L::kPcFootprint] = std::bit_cast<uint32_t>(in.footprint);
    return m.submit(f, Kernel::stack_shadow_pass, uint32_t(pixels), pc);
  }
  if (in.soft) throw GpuError("GpuMap::submit_shadow_pass: a soft pass needs a stack map (a pack built with a light set)");
  const ShadowLight light = m.map_light();
  Impl::Frame& f = m.acquire();
  std::memcpy(f.input_host.mapped, in.positions.data(), pixels * 16);
  std::memcpy(f.normals_host.mapped, in.normals.data(), pixels * 16);
  f.input_bytes = f.normals_bytes = pixels * 16;
  uint32_t pc[L::kPcWords] = {};
  pc[L::kPcCount] = in.width;
  pc[L::kPcHeight] = in.height;
  pc[L::kPcKernel] = in.kernel;
  pc[L::kPcFlags] = (in.neighbour_footprint ? L::kFlagNeighbourFootprint : 0) |
                    (in.receiver_plane ? L::kFlagReceiverPlane : 0);
  for (int i = 0; i < 3; ++i) {
    pc[L::kPcOrigin + i] = std::bit_cast<uint32_t>(light.origin[i]);
    pc[L::kPcAxisU + i] = std::bit_cast<uint32_t>(light.axis_u[i]);
    pc[L::kPcAxisV + i] = std::bit_cast<uint32_t>(light.axis_v[i]);
    pc[L::kPcForward + i] = std::bit_cast<uint32_t>(light.forward[i]);
  }
  pc[L::kPcNear] = std::bit_cast<uint32_t>(light.near_scaled);
  pc[L::kPcNormalOffset] = std::bit_cast<uint32_t>(in.normal_offset);
  pc[L::kPcFootprint] = std::bit_cast<uint32_t>(in.footprint);
  if (m.deep_part) f.out_words = 4;  // the light per channel after the visibility (shadow_pass.comp)
  return m.submit(f, Kernel::shadow_pass, uint32_t(pixels), pc);
}

FrameStats GpuMap::wait(uint64_t frame, std::span<float> out) {
  Impl& m = *impl_;
  m.need_own("wait");
  Impl::Frame* f = m.find(frame);
  if (!f) throw GpuError("GpuMap::wait: frame " + std::to_string(frame) + " is not in flight");
  if (f->in_flight) m.finish(*f);
  if (out.size() < f->count)
    throw GpuError("GpuMap::wait: output of " + std::to_string(out.size()) + " floats, frame has " + std::to_string(f->count));
  std::memcpy(out.data(), f->output_host.mapped, size_t(f->count) * 4);
  f->frame = 0;  // handed out
  return f->stats;
}

FrameStats GpuMap::wait(uint64_t frame, std::span<float> out, std::span<float> light_rgb) {
  Impl& m = *impl_;
  m.need_own("wait");
  Impl::Frame* f = m.find(frame);
  if (!f) throw GpuError("GpuMap::wait: frame " + std::to_string(frame) + " is not in flight");
  if (f->in_flight) m.finish(*f);
  if (out.size() < f->count || light_rgb.size() < size_t(f->count) * 3)
    throw GpuError("GpuMap::wait: output of " + std::to_string(out.size()) + " and light of " +
                   std::to_string(light_rgb.size()) + " floats, frame has " + std::to_string(f->count) +
                   " outputs (1 and 3 floats each)");
  const auto* words = static_cast<const float*>(f->output_host.mapped);
  std::memcpy(out.data(), words, size_t(f->count) * 4);
  if (f->out_words == 4) {
    std::memcpy(light_rgb.data(), words + f->count, size_t(f->count) * 12);
  } else {
    for (uint32_t i = 0; i < f->count; ++i) light_rgb[3 * i] = light_rgb[3 * i + 1] = light_rgb[3 * i + 2] = words[i];
  }
  f->frame = 0;  // handed out
  return f->stats;
}

FrameStats GpuMap::evaluate_deep(std::span<const GpuDeepQuery> queries, std::span<float> out_rgb) {
  Impl& m = *impl_;
  m.need_own("evaluate_deep");
  if (out_rgb.size() != queries.size() * 3) throw GpuError("GpuMap::evaluate_deep: out_rgb needs 3 floats per query");
  if (!m.deep_part) {
    std::fill(out_rgb.begin(), out_rgb.end(), 1.0f);
    return {};
  }
  const uint64_t frame = m.submit_queries(queries, L::kQueryWords, Kernel::evaluate, [](const GpuDeepQuery& q, uint32_t* w) {
    w[L::kQueryX] = std::bit_cast<uint32_t>(q.u);
    w[L::kQueryY] = std::bit_cast<uint32_t>(q.v);
    w[L::kQueryReceiver] = std::bit_cast<uint32_t>(q.depth);
    w[L::kQueryFootprint] = std::bit_cast<uint32_t>(q.width);
    w[L::kQueryR] = L::kDeepQuery;
    w[L::kQueryLevel] = 0;
  }, 4);
  m.answers.resize(queries.size());
  return wait(frame, m.answers, out_rgb);
}

bool GpuMap::has_deep() const { return impl_->deep_part; }

uint32_t GpuMap::sync() {
  Impl& m = *impl_;
  m.need_own("sync");
  uint32_t uploaded = 0;
  for (uint32_t round = 0; round <= m.slot_count; ++round) {
    Impl::Frame& f = m.acquire();
    uint32_t pc[L::kPcWords] = {};
    f.input_bytes = f.normals_bytes = 0;
    const uint64_t frame = m.submit(f, m.sg ? Kernel::stack_evaluate : Kernel::evaluate, 0, pc);  // uploads only
    Impl::Frame* g = m.find(frame);
    m.finish(*g);
    g->frame = 0;
    uploaded += g->stats.slots_uploaded;
    if (g->stats.slots_uploaded == 0) break;
  }
  return uploaded;
}

GpuStats GpuMap::stats() const {
  GpuStats s = impl_->totals;
  s.resident_slots = impl_->resident;
  s.deep_tiles = impl_->deep_part ? impl_->deep.count() : 0;
  s.deep_tiles_dropped = impl_->deep_part ? impl_->deep.dropped() : 0;
  s.pool_bytes = impl_->pool_bytes;
  s.page_table_bytes = impl_->page_shadow.size() * 4;
  s.validation_messages = impl_->ctx->validation_messages();  // own-device mode's layer only
  return s;
}

std::span<const GpuMap::FeedbackTile> GpuMap::last_feedback() const { return impl_->feedback; }

const std::string& GpuMap::device_name() const { return impl_->ctx->device_name(); }

bool GpuMap::is_stack() const { return impl_->sg != nullptr; }

}  // namespace st::gpu
