#include "tiles/core/stack_slices.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>

#include "common/error.hpp"
#include "tiles/core/dagmh_format.hpp"
#include "tiles/core/dagmh_view.hpp"
#include "tiles/core/encoding.hpp"
#include "tiles/core/mh_octree_format.hpp"
#include "tiles/core/mh_quadtree_format.hpp"
#include "tiles/core/pack_format.hpp"
#include "tiles/core/plane_pack.hpp"
#include "tiles/core/plane_tile.hpp"

namespace st {
namespace {

uint32_t u32_at(std::span<const uint8_t> b, size_t off) {
  uint32_t v;
  std::memcpy(&v, b.data() + off, 4);
  return v;
}

[[noreturn]] void bad(const std::string& field, size_t at, const std::string& why) {
  throw FormatError("slice tiles: " + field + " at byte " + std::to_string(at) + ": " + why);
}

}  // namespace

bool is_slice_tiles(std::span<const uint8_t> bytes) {
  return bytes.size() >= 4 && u32_at(bytes, 0) == kSliceTilesMagic;
}

SliceTiles SliceTiles::open(std::span<const uint8_t> b) {
  if (b.size() < kSliceTilesHeaderBytes) bad("header", 0, std::to_string(b.size()) + " bytes, below the 16-byte header");
  if (u32_at(b, 0) != kSliceTilesMagic) bad("magic", 0, "not \"STSL\"");
  uint16_t version;
  std::memcpy(&version, b.data() + 4, 2);
  if (version != kSliceTilesVersion) bad("version", 4, std::to_string(version) + ", expected 1");
  SliceTiles t;
  t.xy_level_ = b[6];
  t.w_level_ = b[7];
  if (t.xy_level_ > moct::kMaxXyLevel) bad("xy_level", 6, std::to_string(t.xy_level_) + " above 20");
  if (t.w_level_ > moct::kMaxWLevel) bad("w_level", 7, std::to_string(t.w_level_) + " above 12");
  if (u32_at(b, 8) != b.size()) bad("byte_size", 8, std::to_string(u32_at(b, 8)) + ", the buffer holds " + std::to_string(b.size()));
  if (u32_at(b, 12) != 0) bad("reserved", 12, "not zero");
  const uint64_t count = uint64_t(1) << t.w_level_;
  const uint64_t first = kSliceTilesHeaderBytes + kSliceTilesEntryBytes * count;
  if (first > b.size()) bad("entries", kSliceTilesHeaderBytes, std::to_string(count) + " entries run past the buffer");
  t.byte_size_ = b.size();
  t.slot_.assign(count, -1);
  t.value_.assign(count, 0.0f);
  constexpr float kUnknown = std::numeric_limits<float>::quiet_NaN();  // no receiver compares against NaN
  t.bounds_.assign(count, {kUnknown, kUnknown});
  std::vector<uint64_t> first_slice;  // per buffer: the first slice that names it
  std::vector<uint64_t> starts, sizes;  // buffers in order of first use
  uint64_t next = first;         // where the next new buffer must start
  for (uint64_t w = 0; w < count; ++w) {
    const size_t at = kSliceTilesHeaderBytes + kSliceTilesEntryBytes * w;
    const uint32_t off = u32_at(b, at), word = u32_at(b, at + 4);
    if (off == 0) {
      float v;
      std::memcpy(&v, &word, 4);
      if (!std::isfinite(v)) bad("entry " + std::to_string(w), at + 4, "constant not finite");
      t.value_[w] = v;
      t.bounds_[w] = {v, v};
      continue;
    }
    size_t s = 0;
    while (s < starts.size() && starts[s] != off) ++s;
    if (s < starts.size()) {  // a buffer an earlier slice named: the same size
      if (word != sizes[s]) bad("entry " + std::to_string(w), at + 4, "size differs from the earlier slice's of that buffer");
      t.slot_[w] = int32_t(s);
      t.bounds_[w] = t.bounds_[first_slice[s]];
      continue;
    }
    if (off != next) bad("entry " + std::to_string(w), at, "offset " + std::to_string(off) + ", the next buffer starts at " + std::to_string(next));
    if (word < 4 || uint64_t(off) + word > b.size())
      bad("entry " + std::to_string(w), at + 4, "size " + std::to_string(word) + " runs past the buffer");
    const uint64_t end = uint64_t(off) + word, padded = (end + 3) & ~uint64_t(3);
    if (padded > b.size()) bad("padding", end, "runs past the buffer");
    for (uint64_t i = end; i < padded; ++i)
      if (b[i] != 0) bad("padding", i, "not zero");
    const std::span<const uint8_t> sub = b.subspan(off, word);
    std::unique_ptr<Evaluator> ev;
    try {
      // DAG-MH, or MMH by its magic ("Mixed tiles"), or plane blocks over either ("STPN",
      // PLANES.md; open_plane_tile refuses a plane tile inside another)
      ev = open_encoded(Encoding::dagmh, sub);
    } catch (const Error& e) {
      bad("slice " + std::to_string(w) + "'s tile", off, e.what());
    }
    if (ev->finest_level() != t.xy_level_)
      bad("slice " + std::to_string(w) + "'s tile", off,
          "finest level " + std::to_string(ev->finest_level()) + ", the cell's is " + std::to_string(t.xy_level_));
    t.planes_ = t.planes_ || is_plane_buffer(sub);
    t.wide_planes_ = t.wide_planes_ || (plane_tile_features(sub) & kFeatureWidePlaneBlocks);
    t.slot_[w] = int32_t(t.evals_.size());
    const dagmh::View* view = dagmh_view(*ev);
    t.views_.push_back(view ? *view : dagmh::View{});
    t.has_view_.push_back(view != nullptr);
    // An MMH tile (validated by open_encoded as such): its tree for the lookups' walks.
    const bool mmh = !view && sub.size() >= mhq::kHeaderFixedSize && u32_at(sub, 0) == mhq::kMagicMmh;
    t.mmh_tree_.push_back(mmh ? sub.data() + mhq::tree_offset(sub[mhq::kOffLevels]) : nullptr);
    t.mmh_root_leaf_.push_back(mmh && (sub[mhq::kOffFlags] & mhq::kFlagRootLeaf));
    if (view && view->value_count > 0) {  // every answer is one of the stored values (validated indices)
      float lo = view->value(0), hi = lo;
      bool nan = std::isnan(lo);
      for (uint32_t i = 1; i < view->value_count; ++i) {
        const float v = view->value(i);
        nan = nan || std::isnan(v);
        lo = std::min(lo, v);
        hi = std::max(hi, v);
      }
      if (!nan) t.bounds_[w] = {lo, hi};
    }
    first_slice.push_back(w);
    t.evals_.push_back(std::move(ev));
    starts.push_back(off);
    sizes.push_back(word);
    next = padded;
  }
  if (next != b.size()) bad("byte_size", next, std::to_string(b.size() - next) + " bytes after the last buffer");
  t.build_records();
  return t;
}

namespace {

// A record's DAG-MH fields from view v (SliceTiles::Record): false, with r untouched, where
// they do not fit (a dictionary, a section before the skip table or 4 GiB past it, a skip
// level over 255, another finest level), which a record answers through the evaluator
// instead. Every check comes before the first write.
bool compact_view(const dagmh::View& v, SliceTiles::Record& r) {
  if (v.dict_node_words || v.dict_treelet_count || !v.skip) return false;
  if (v.skip_level > 0xFF || v.finest_level != r.xy_level) return false;
  uint32_t off[4];
  const uint8_t* const at[4] = {v.nodes, v.treelets, v.chunks, v.multipliers};
  for (int i = 0; i < 4; ++i) {
    if (at[i] < v.skip || uint64_t(at[i] - v.skip) > 0xFFFFFFFFull) return false;
    off[i] = uint32_t(at[i] - v.skip);
  }
  r.base = v.skip, r.nodes = off[0], r.treelets = off[1], r.chunks = off[2], r.multipliers = off[3];
  r.root_ref = v.root_ref, r.skip_level = uint8_t(v.skip_level);
  return true;
}

}  // namespace

void SliceTiles::build_records() {
  records_.assign(slot_.size(), Record{});
  for (uint32_t w = 0; w < slices(); ++w) {
    Record& r = records_[w];
    r.lo = bounds_[w].lo, r.hi = bounds_[w].hi, r.xy_level = xy_level_;
    if (is_constant(w)) {
      r.kind = RecordKind::constant;
    } else if (const dagmh::View* v = view(w); v && compact_view(*v, r)) {
      r.kind = RecordKind::view;
    } else if (const uint8_t* tree = mmh_tree_[size_t(slot_[w])]) {
      r.kind = RecordKind::mmh, r.eval = &evaluator(w);
      r.base = tree, r.mmh_root_leaf = mmh_root_leaf_[size_t(slot_[w])];
    } else {
      r.kind = RecordKind::evaluator, r.eval = &evaluator(w);
    }
  }
}

bool is_grouped_slice_tiles(std::span<const uint8_t> bytes) {
  return bytes.size() >= 4 && u32_at(bytes, 0) == kGroupedSliceTilesMagic;
}

namespace {

[[noreturn]] void bad_grouped(const std::string& field, size_t at, const std::string& why) {
  throw FormatError("grouped slice tiles: " + field + " at byte " + std::to_string(at) + ": " + why);
}

}  // namespace

void ungroup_slice_tiles(std::span<uint8_t> b, uint32_t* plane_features) {
  const size_t size = b.size();
  if (size < kSliceTilesHeaderBytes) bad_grouped("header", 0, std::to_string(size) + " bytes, below the 16-byte header");
  if (u32_at(b, 0) != kGroupedSliceTilesMagic) bad_grouped("magic", 0, "not \"STSP\"");
  if (b[7] > moct::kMaxWLevel) bad_grouped("w_level", 7, std::to_string(b[7]) + " above 12");
  if (u32_at(b, 8) != size) bad_grouped("byte_size", 8, std::to_string(u32_at(b, 8)) + ", the buffer holds " + std::to_string(size));
  const uint64_t count = uint64_t(1) << b[7];
  const uint64_t first = kSliceTilesHeaderBytes + kSliceTilesEntryBytes * count;
  if (first > size) bad_grouped("entries", kSliceTilesHeaderBytes, std::to_string(count) + " entries run past the buffer");
  struct Buf {
    uint64_t off = 0, size = 0, head = 0, structure = 0;  // structure: DAG-MH only
    bool dagmh = false, plane = false;  // plane: a packed plane slice, whole among the heads
    std::vector<uint8_t> role;  // MMH only
  };
  std::vector<Buf> bufs;
  uint64_t next = first;
  for (uint64_t w = 0; w < count; ++w) {
    const size_t at = kSliceTilesHeaderBytes + kSliceTilesEntryBytes * w;
    const uint32_t off = u32_at(b, at), word = u32_at(b, at + 4);
    if (off == 0 || off < next) continue;  // a constant, or a buffer an earlier slice named
    if (off != next) bad_grouped("entry " + std::to_string(w), at, "offset " + std::to_string(off) + ", the next buffer starts at " + std::to_string(next));
    if (word < 4 || uint64_t(off) + word > size)
      bad_grouped("entry " + std::to_string(w), at + 4, "size " + std::to_string(word) + " runs past the buffer");
    Buf f;
    f.off = off, f.size = word;
    bufs.push_back(std::move(f));
    next = (uint64_t(off) + word + 3) & ~uint64_t(3);
  }
  if (next != size) bad_grouped("byte_size", 8, "the buffers end at byte " + std::to_string(next) + ", not at the end");

  thread_local std::vector<uint8_t> src;
  src.assign(b.begin(), b.end());
  std::memset(b.data() + first, 0, size - first);
  uint64_t at = first;  // read position in src
  auto take = [&](uint64_t n, const char* part) {
    if (n > size - at) bad_grouped(part, at, std::to_string(n) + " bytes run past the buffer");
    const uint64_t r = at;
    at += n;
    return r;
  };
  auto copy = [&](uint64_t to, uint64_t n, const char* part) {
    const uint64_t from = take(n, part);
    if (n) std::memcpy(b.data() + to, src.data() + from, n);
  };
  for (Buf& f : bufs) {  // heads
    if (size - at < 8) bad_grouped("head", at, "runs past the buffer");
    const uint32_t magic = u32_at(src, at);
    if (magic == dagmh::kMagic) {
      f.dagmh = true, f.head = 32;
      if (f.size < f.head + 8) bad_grouped("head", at, "a DAG-MH buffer of " + std::to_string(f.size) + " bytes");
      const uint64_t base = at;
      copy(f.off, f.head, "head");
      const uint32_t S = src[base + 9];
      if (S > 6) bad_grouped("head", base + 9, "skip level " + std::to_string(S) + " above 6");
      const uint64_t nw = u32_at(src, base + 16), tc = u32_at(src, base + 20), vc = u32_at(src, base + 24);
      f.structure = (S ? uint64_t(16) << (2 * S) : 0) + 4 * nw + 12 * tc + 20 * ((vc + 31) / 32);
      if (f.structure > f.size - f.head) bad_grouped("head", base + 16, "sections run past the buffer's " + std::to_string(f.size) + " bytes");
    } else if (magic == mhq::kMagicMmh) {
      const uint32_t levels = src[at + 6];
      if (levels < 1 || levels > mhq::kMaxLevels) bad_grouped("head", at + 6, "levels " + std::to_string(levels));
      f.head = mhq::tree_offset(levels);
      if (f.size < f.head || (f.size - f.head) % 4) bad_grouped("head", at, "an MMH buffer of " + std::to_string(f.size) + " bytes");
      copy(f.off, f.head, "head");
    } else if (is_packed_plane_tile(std::span<const uint8_t>(src).subspan(at, 8))) {
      f.plane = true, f.head = f.size;
      const uint64_t base = at;
      copy(f.off, f.head, "head");
      if (plane_features) *plane_features |= kFeaturePlaneTiles | plane_tile_features(b.subspan(f.off, std::min<uint64_t>(f.size, 8)));
      try {
        unpack_plane_tile(b.subspan(f.off, f.size));
      } catch (const FormatError& e) {
        bad_grouped("plane slice", base, e.what());
      }
    } else {
      bad_grouped("head", at, "neither a DAG-MH, an MMH nor a packed plane buffer");
    }
  }
  for (const Buf& f : bufs)
    if (f.dagmh) copy(f.off + f.head, f.structure, "structure");
  for (Buf& f : bufs) {
    if (f.dagmh || f.plane) continue;
    const uint64_t tree = f.off + f.head;
    mmh_word_roles((f.size - f.head) / 4, b[f.off + mhq::kOffFlags] & mhq::kFlagRootLeaf, f.role, [&](uint64_t i) {
      copy(tree + 4 * i, 4, "node words");
      return u32_at(b, tree + 4 * i);
    });
  }
  for (const Buf& f : bufs)
    if (f.dagmh) copy(f.off + f.head + f.structure, f.size - f.head - f.structure, "multipliers");
  for (const Buf& f : bufs)
    for (uint64_t i = 0; i < f.role.size(); ++i)
      if (f.role[i] == 2) copy(f.off + f.head + 4 * i, 4, "values");
  for (uint64_t i = at; i < size; ++i)
    if (src[i] != 0) bad_grouped("tail", i, "not zero");
  const uint32_t magic = kSliceTilesMagic;
  std::memcpy(b.data(), &magic, 4);
}

StackTile StackTile::open(std::span<const uint8_t> bytes) {
  StackTile t;
  if (is_slice_tiles(bytes))
    t.slices_ = std::make_unique<SliceTiles>(SliceTiles::open(bytes));
  else
    t.octree_ = std::make_unique<MhOctree>(MhOctree::open(bytes));  // refuses anything but "STOC"
  return t;
}

}  // namespace st
