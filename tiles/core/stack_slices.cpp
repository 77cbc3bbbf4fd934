#include "tiles/core/stack_slices.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>

#include "common/error.hpp"
#include "tiles/core/dagmh_view.hpp"
#include "tiles/core/encoding.hpp"
#include "tiles/core/mh_octree_format.hpp"

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
      ev = open_encoded(Encoding::dagmh, sub);  // DAG-MH, or MMH by its magic ("Mixed tiles")
    } catch (const Error& e) {
      bad("slice " + std::to_string(w) + "'s tile", off, e.what());
    }
    if (ev->finest_level() != t.xy_level_)
      bad("slice " + std::to_string(w) + "'s tile", off,
          "finest level " + std::to_string(ev->finest_level()) + ", the cell's is " + std::to_string(t.xy_level_));
    t.slot_[w] = int32_t(t.evals_.size());
    const dagmh::View* view = dagmh_view(*ev);
    t.views_.push_back(view ? *view : dagmh::View{});
    t.has_view_.push_back(view != nullptr);
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
  return t;
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
