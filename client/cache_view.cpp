// CacheView (shadowtile/cache_view.hpp) over the RemoteMap behind a Map: the immutable
// tables copied into plain structs once, the slot diff under the cache's lock.
#include "shadowtile/cache_view.hpp"

#include <algorithm>
#include <cassert>
#include <mutex>
#include <stdexcept>

#include "client/deep_part.hpp"
#include "client/map_access.hpp"
#include "client/remote_map.hpp"
#include "tiles/core/dagmh_validate.hpp"
#include "tiles/core/stack_grid.hpp"

namespace st::client {

struct CacheView::Impl {
  Map map;  // holds the RemoteMap (and so every table below) open
  const RemoteMap* rm = nullptr;
  CacheShape shape;
  std::vector<CacheEntry> skip_entries;
  std::vector<CacheEntry> stack_cells;
  std::vector<LightParams> stack_lights;
  StackTables stack;
  bool is_stack = false;
  // changed_slots' place in the cache's change journal (tile_cache.hpp) for the consumer's
  // `known` array it last served; slots that consumer left for later (visit false); and a
  // scratch list of the slots to compare with a mark per slot (each compared once). Sized
  // once: a call allocates nothing.
  std::mutex journal_mu;
  bool cursor_valid = false;
  uint64_t cursor = 0;
  const uint64_t* known_data = nullptr;
  size_t known_size = 0;
  std::vector<uint32_t> pending, scratch;
  std::vector<uint8_t> marked;
};

CacheView::CacheView(const Map& map) : impl_(std::make_unique<Impl>()) {
  if (!map.valid()) throw std::runtime_error("CacheView: the Map is not open (default-constructed)");
  Impl& m = *impl_;
  m.map = map;
  m.rm = &MapAccess::remote(m.map);
  const RemoteMap& rm = *m.rm;
  m.shape.finest_level = rm.header().map_level;
  m.shape.skip_level = rm.grid().levels;
  m.shape.encoding = uint32_t(rm.header().encoding);
  uint64_t journal_capacity = 0;
  rm.inspect_cache([&](const TileCache& c) {
    m.shape.slot_count = c.slot_count();
    m.shape.slot_bytes = c.slot_bytes();
    journal_capacity = c.journal_capacity();
  });
  m.pending.reserve(m.shape.slot_count);
  m.scratch.reserve(m.shape.slot_count + journal_capacity);
  m.marked.assign(m.shape.slot_count, 0);
  m.skip_entries.reserve(rm.grid().entries.size());
  for (const GridEntry& e : rm.grid().entries) m.skip_entries.push_back({e.value, uint32_t(e.kind), e.index_levels});
  if (const StackGrid* g = rm.stack_grid()) {
    // A cell's tile is an MH octree or per-slice 2D tiles (stack_slices.hpp); the GLSL
    // (st_stack.glsl) tells them by their magic, so both kinds of stack pack pass.
    m.is_stack = true;
    m.shape.slices = g->slices;
    m.stack.xy_level = g->geo.n;
    m.stack.w_level = g->geo.k;
    m.stack.slices = g->slices;
    m.stack.skip_level = g->skip_level;
    for (const std::vector<float>& level : g->coarse) m.stack.coarse.emplace_back(level);
    m.stack_cells.reserve(g->entries.size());
    for (const StackEntry& e : g->entries) m.stack_cells.push_back({e.value, e.kind, 0});
    for (const auto& l : g->lights) m.stack_lights.push_back({uint32_t(g->light_kind), l});
    m.stack.cells = m.stack_cells;
    m.stack.lights = m.stack_lights;
  }
}

CacheView::~CacheView() = default;

const CacheShape& CacheView::shape() const { return impl_->shape; }
std::span<const float> CacheView::skip_coarse() const { return impl_->rm->grid().coarse; }
std::span<const CacheEntry> CacheView::skip_entries() const { return impl_->skip_entries; }

PreviewTables CacheView::preview() const {
  const MapPreview& pv = impl_->rm->preview();
  PreviewTables t;
  t.levels = pv.levels();
  t.mask_words = uint32_t(MapPreview::words(pv.levels()));
  t.ordinals = pv.ordinals();
  t.bases = pv.bases();
  t.entry_values = pv.entry_values();
  t.masks = pv.masks();
  t.values = pv.values();
  return t;
}

std::span<const uint8_t> CacheView::dictionary() const {
  const dagmh::Dictionary* d = impl_->rm->dictionary().get();
  return d ? d->bytes() : std::span<const uint8_t>{};
}

LightParams CacheView::light() const { return {uint32_t(impl_->rm->header().light_kind), impl_->rm->header().light}; }

const StackTables* CacheView::stack() const { return impl_->is_stack ? &impl_->stack : nullptr; }

uint64_t CacheView::stack_cell_tile(uint64_t cell) const {
  const StackGrid* g = impl_->rm->stack_grid();
  return g && cell < g->entries.size() ? g->tile_id(cell) : kNoTile;
}

bool CacheView::stack_tile_cell(uint64_t tile, uint64_t& cell) const {
  const StackGrid* g = impl_->rm->stack_grid();
  return g && g->cell_of(tile, cell);
}

size_t CacheView::changed_slots_impl(std::span<uint64_t> known, void* visit,
                                     bool (*call)(void*, const SlotChange&)) const {
  Impl& m = *impl_;
  std::lock_guard guard(m.journal_mu);
  size_t n = 0;
  m.rm->inspect_cache([&](const TileCache& c) {
    const uint32_t slots = std::min<uint32_t>(c.slot_count(), uint32_t(known.size()));
    auto compare = [&](uint32_t s) {
      // The slot's own state, not a probe of the cache's page table per changed slot.
      const uint64_t want = c.slot_resident(s) ? c.slot_tile(s) : kNoTile;
      assert(want == kNoTile || (c.lookup(want).state == PageState::resident && c.lookup(want).slot == s));
      if (known[s] == want) return;
      SlotChange ch;
      ch.slot = s;
      ch.tile = want;
      if (want != kNoTile) ch.bytes = c.tile_bytes(s);
      ++n;
      if (call(visit, ch)) known[s] = want;
      else m.pending.push_back(s);  // left for later: compared again next call
    };
    // The journal serves the consumer it last served (the same `known`): the slots it
    // left for later and those changed since, each once. Anything else compares every slot.
    bool scan = !m.cursor_valid || known.data() != m.known_data || known.size() != m.known_size;
    m.scratch.clear();
    if (!scan) {
      auto add = [&](uint32_t s) {
        if (s < slots && !m.marked[s]) m.marked[s] = 1, m.scratch.push_back(s);
      };
      for (uint32_t s : m.pending) add(s);
      scan = !c.changes_since(m.cursor, add);
    }
    for (uint32_t s : m.scratch) m.marked[s] = 0;
    m.pending.clear();
    if (scan) {
      for (uint32_t s = 0; s < slots; ++s) compare(s);
    } else {
      // The slots are scattered and cold (the fetch thread wrote them): each one's record
      // and `known` word are asked for kSlotsAhead slots before it is compared, and the
      // bytes of a resident one kBytesAhead before (its record is in by then), so the
      // misses overlap instead of waiting on each other. Loads only: nothing changes.
      constexpr size_t kSlotsAhead = 8, kBytesAhead = 4;
      const size_t count = m.scratch.size();
      for (size_t i = 0; i < count; ++i) {
        if (i + kSlotsAhead < count) {
          const uint32_t s = m.scratch[i + kSlotsAhead];
          c.prefetch_slot(s);
          __builtin_prefetch(&known[s]);
        }
        if (i + kBytesAhead < count) {
          const uint32_t s = m.scratch[i + kBytesAhead];
          if (c.slot_resident(s)) {
            const std::span<const uint8_t> b = c.tile_bytes(s);
            const auto first = reinterpret_cast<uintptr_t>(b.data()) & ~uintptr_t(63);
            for (uintptr_t p = first; p < reinterpret_cast<uintptr_t>(b.data() + b.size()); p += 64)
              __builtin_prefetch(reinterpret_cast<const void*>(p));
          }
        }
        compare(m.scratch[i]);
      }
    }
    m.cursor = c.journal_end();
    m.cursor_valid = true;
    m.known_data = known.data();
    m.known_size = known.size();
  });
  return n;
}

bool CacheView::has_deep() const { return impl_->rm->deep() != nullptr; }

uint64_t CacheView::deep_generation() const {
  const DeepPart* d = impl_->rm->deep();
  return d ? d->generation() : 0;
}

DeepShape CacheView::deep_tiles_impl(void* visit, void (*call)(void*, const DeepTile&)) const {
  DeepShape shape;
  const DeepPart* d = impl_->rm->deep();
  if (!d) return shape;
  d->inspect([&](uint32_t level, uint32_t side_bits) { shape = {level, side_bits}; },
             [&](uint32_t tx, uint32_t ty, std::span<const uint8_t> bytes) { call(visit, DeepTile{tx, ty, bytes}); });
  return shape;
}

DeepShape CacheView::deep_directory_impl(void* visit, void (*call)(void*, std::span<const uint8_t>)) const {
  DeepShape shape;
  const DeepPart* d = impl_->rm->deep();
  if (!d) return shape;
  d->inspect_directory([&](uint32_t level, uint32_t side_bits, std::span<const uint8_t> bitmap) {
    shape = {level, side_bits};
    call(visit, bitmap);
  });
  return shape;
}

size_t CacheView::want_deep_tiles(std::span<const DeepWant> tiles) const {
  const DeepPart* d = impl_->rm->deep();
  if (!d) return 0;
  constexpr size_t kChunk = 256;  // a frame's feedback, converted on the stack: no allocation
  std::array<uint32_t, 2> buf[kChunk];
  size_t queued = 0;
  for (size_t i = 0; i < tiles.size(); i += kChunk) {
    const size_t n = std::min(kChunk, tiles.size() - i);
    for (size_t j = 0; j < n; ++j) buf[j] = {tiles[i + j].tx, tiles[i + j].ty};
    queued += d->want(std::span<const std::array<uint32_t, 2>>(buf, n));
  }
  return queued;
}

std::array<float, 3> CacheView::deep_transmittance(double u, double v, float d, double width) const noexcept {
  const DeepPart* p = impl_->rm->deep();
  return p ? p->lookup(u, v, d, width) : std::array<float, 3>{1, 1, 1};
}

size_t CacheView::want_tiles(std::span<const WantedTile> tiles) const {
  // Small batches (a frame's feedback): converted on the stack in chunks, no allocation.
  constexpr size_t kChunk = 256;
  RemoteMap::WantedTile buf[kChunk];
  size_t queued = 0;
  for (size_t i = 0; i < tiles.size(); i += kChunk) {
    const size_t n = std::min(kChunk, tiles.size() - i);
    for (size_t j = 0; j < n; ++j) {
      const WantedTile& w = tiles[i + j];
      buf[j].tile = w.tile;
      buf[j].entry.value = w.entry.value;
      buf[j].entry.kind = EntryKind(w.entry.kind & 0xFFu);
      buf[j].entry.index_levels = uint8_t(w.entry.index_levels);
      buf[j].priority = w.priority;
    }
    queued += impl_->rm->want_tiles(std::span<const RemoteMap::WantedTile>(buf, n));
  }
  return queued;
}

}  // namespace st::client
