#include "tiles/core/plane_pack.hpp"

#include <algorithm>
#include <bit>
#include <cstring>
#include <string>

#include "common/bytes.hpp"
#include "common/error.hpp"
#include "tiles/core/mh_quadtree_format.hpp"
#include "tiles/core/morton.hpp"
#include "tiles/core/pack_format.hpp"
#include "tiles/core/plane_format.hpp"
#include "tiles/core/plane_tile.hpp"

namespace st {

namespace plane_pack {

inline constexpr uint32_t kMagic = 0x51505453u;           // bytes "STPQ"
inline constexpr uint32_t kMagicPredicted = 0x4C505453u;  // bytes "STPL": labels predicted
// A labelled block's use byte in STPL: the use mask (bits 0..3), the prediction mode (bits
// 4..5: 0 none, 1 the least plane, 2 the greatest), all predicted (bit 6: no label bytes).
inline constexpr uint32_t kModeNone = 0, kModeLeast = 1, kModeGreatest = 2, kModes = 3;
inline constexpr uint32_t kModeShift = 4, kAllPredicted = 0x40;
// A wide labelled block's use byte (STPQ and STPL), its class byte 0: its 8 palette entries
// follow in the planes stream as indices, its 24 label bytes (3 bit planes) in the labels.
inline constexpr uint8_t kWideUse = 0x80;
// STPL header byte 7 (the STPN flags, 0): the inner buffer's kind when its header's
// derivable fields are left out (zeros in place): 0 none left out, 1 MH, 2 MMH.
inline constexpr uint32_t kInnerKept = 0, kInnerMh = 1, kInnerMmh = 2;
// The inner MH/MMH header bytes left out: magic, version and levels (0..6), byte_size (12..15).
inline constexpr size_t kInnerLeftOut[2][2] = {{0, 7}, {12, 16}};

// The inner kind code of an MH/MMH inner buffer `inner` whose derivable header fields
// (magic, version, levels, byte_size) agree with its plane tile (finest level + 1 `levels`);
// kInnerKept otherwise.
uint32_t inner_kind(std::span<const uint8_t> inner, uint32_t levels) {
  if (inner.size() < mhq::kHeaderFixedSize) return kInnerKept;
  const uint32_t magic = load_le<uint32_t>(inner.data());
  if (magic != mhq::kMagicMh && magic != mhq::kMagicMmh) return kInnerKept;
  if (load_le<uint16_t>(inner.data() + mhq::kOffVersion) != mhq::kVersion || inner[mhq::kOffLevels] != levels ||
      load_le<uint32_t>(inner.data() + mhq::kOffByteSize) != inner.size())
    return kInnerKept;
  return magic == mhq::kMagicMh ? kInnerMh : kInnerMmh;
}
// Quadtree node kinds (plane_pack.hpp), 2 bits each.
inline constexpr uint8_t kNodeEmpty = 0, kNodeSplit = 1, kNodePlane = 2, kNodeLabels = 3;
inline constexpr uint32_t kTexels = 64;       // a labelled block's texels (8x8)
inline constexpr size_t kLabelBytes = 16;     // 2-bit labels (plane_format.hpp)
inline constexpr size_t kOneBitLabelBytes = 8;

[[noreturn]] void fail(const std::string& field, size_t offset, const std::string& why) {
  throw FormatError("packed plane tile: " + field + " at byte " + std::to_string(offset) + ": " + why);
}

// Texel i's 2-bit label in a labelled block's 16 label bytes.
uint32_t label_of(const uint8_t* bits, uint32_t i) { return (bits[i / 4] >> (2 * (i % 4))) & 3u; }

// The palette entries a labelled block's labels use, as a 4-bit mask (a unpack of a real
// level's tiles runs this on every labelled block: word operations, not 64 texels).
uint32_t used_entries(const uint8_t* bits) {
  constexpr uint64_t kLow = 0x5555555555555555ull;
  uint32_t used = 0;
  for (uint32_t half = 0; half < 2; ++half) {
    const uint64_t w = load_le<uint64_t>(bits + 8 * half), b0 = w & kLow, b1 = (w >> 1) & kLow;
    used |= uint32_t((~b1 & ~b0 & kLow) != 0) | uint32_t((~b1 & b0) != 0) << 1 | uint32_t((b1 & ~b0 & kLow) != 0) << 2 |
            uint32_t((b1 & b0) != 0) << 3;
  }
  return used;
}

// Eight texels' one-bit labels (a byte, texel k in bit k) as their 2-bit labels (16 bits):
// `low` where the bit is clear, `high` where it is set.
uint16_t widen_labels(uint8_t byte, uint32_t low, uint32_t high) {
  uint32_t set = 0;  // each bit doubled
  for (uint32_t k = 0; k < 8; ++k) set |= ((uint32_t(byte) >> k) & 1u) * (3u << (2 * k));
  const uint32_t lows = low * 0x5555u, flips = (low ^ high) * 0x5555u;
  return uint16_t(lows ^ (set & flips));
}

// The label each texel of a labelled block gets under each prediction mode: kModeLeast the
// used palette entry whose plane is least at the texel (a crease's near surface),
// kModeGreatest the greatest, ties to the lower entry; kModeNone entry 0 (more than two
// used entries) or the lower used entry (two), so its residual is the plain label. `table`
// is the tile's plane table; palette entries index it (checked by the caller); (x0, y0) the
// block's corner in tile texels. Plane values are summed modulo 2^64 (what the STPN decoder
// sums for a valid tile; an invalid one is refused after unpacking).
struct Predictions {
  uint8_t label[kModes][kTexels];
};

void predict_labels(const uint8_t* table, const uint32_t* palette, uint32_t used, uint32_t x0, uint32_t y0, Predictions& p) {
  using namespace planes;
  const uint32_t low = uint32_t(std::countr_zero(used));
  std::fill(p.label[kModeNone], p.label[kModeNone] + kTexels, uint8_t(std::popcount(used) == 2 ? low : 0));
  int64_t least[kTexels] = {}, greatest[kTexels] = {};
  for (uint32_t e = low; e < kPalette; ++e) {
    if (!(used >> e & 1u)) continue;
    const uint8_t* t = table + size_t(palette[e]) * kEntrySize;
    const uint64_t a = load_le<uint64_t>(t + kOffA), b = load_le<uint64_t>(t + kOffB), c = load_le<uint64_t>(t + kOffC);
    uint64_t row = a + b * uint64_t(x0) + c * uint64_t(y0);  // the texel (x0, y0 + y), then along x
    for (uint32_t y = 0; y < 8; ++y, row += c) {
      uint64_t at = row;
      for (uint32_t x = 0; x < 8; ++x, at += b) {
        const uint32_t i = 8 * y + x;
        const int64_t v = int64_t(at);
        if (e == low || v < least[i]) least[i] = v, p.label[kModeLeast][i] = uint8_t(e);
        if (e == low || v > greatest[i]) greatest[i] = v, p.label[kModeGreatest][i] = uint8_t(e);
      }
    }
  }
}

// The residual of labels `lab` against prediction `pred` (two used entries: one bit a
// texel, set where exactly one of them is the higher entry; more: the 2-bit XOR) into
// `bits` (8 or 16 bytes).
void residual(const uint8_t* lab, const uint8_t* pred, uint32_t used, uint8_t* bits) {
  if (std::popcount(used) == 2) {
    const uint32_t high = 31 - uint32_t(std::countl_zero(used));
    uint64_t word = 0;
    for (uint32_t i = 0; i < kTexels; ++i) word |= uint64_t((lab[i] == high) != (pred[i] == high)) << i;
    for (uint32_t k = 0; k < kOneBitLabelBytes; ++k) bits[k] = uint8_t(word >> (8 * k));
    return;
  }
  std::fill(bits, bits + kLabelBytes, uint8_t(0));
  for (uint32_t i = 0; i < kTexels; ++i) bits[i / 4] |= uint8_t((lab[i] ^ pred[i]) << (2 * (i % 4)));
}

// The mode a block's labels `lab` (each a used entry) are stored under: the fewest texels
// not predicted, ties to the lower mode (the writer's choice, and the unpacker's canonical
// check); `misses` gets that count.
uint32_t best_mode(const Predictions& p, const uint8_t* lab, uint32_t& misses) {
  uint32_t mode = kModeNone;
  misses = kTexels + 1;
  for (uint32_t m = 0; m < kModes; ++m) {
    uint32_t n = 0;
    for (uint32_t i = 0; i < kTexels; ++i) n += lab[i] != p.label[m][i];
    if (n < misses) misses = n, mode = m;
  }
  return mode;
}

// Two used entries (`low`, `high`), as bit masks (bit i: texel i): where the higher entry's
// plane is less than the lower's (there kModeLeast predicts `high`) and where it is greater
// (kModeGreatest does); the same predictions as predict_labels, without the label arrays.
void predict_two(const uint8_t* table, uint32_t low_plane, uint32_t high_plane, uint32_t x0, uint32_t y0, uint64_t& less,
                 uint64_t& greater) {
  using namespace planes;
  const uint8_t* tl = table + size_t(low_plane) * kEntrySize;
  const uint8_t* th = table + size_t(high_plane) * kEntrySize;
  // Each plane's value summed modulo 2^64 along the rows, compared as signed integers.
  const uint64_t al = load_le<uint64_t>(tl + kOffA), bl = load_le<uint64_t>(tl + kOffB), cl = load_le<uint64_t>(tl + kOffC);
  const uint64_t ah = load_le<uint64_t>(th + kOffA), bh = load_le<uint64_t>(th + kOffB), ch = load_le<uint64_t>(th + kOffC);
  uint64_t row_l = al + bl * uint64_t(x0) + cl * uint64_t(y0), row_h = ah + bh * uint64_t(x0) + ch * uint64_t(y0);
  less = greater = 0;
  for (uint32_t y = 0; y < 8; ++y, row_l += cl, row_h += ch) {
    uint64_t l = row_l, h = row_h;
    for (uint32_t x = 0; x < 8; ++x, l += bl, h += bh) {
      less |= uint64_t(int64_t(h) < int64_t(l)) << (8 * y + x);
      greater |= uint64_t(int64_t(h) > int64_t(l)) << (8 * y + x);
    }
  }
}

// The mode two-entry labels `high` (bit i: texel i takes the higher entry) are stored
// under (best_mode's rule on masks); `misses` gets its count.
uint32_t best_mode_two(uint64_t high, uint64_t less, uint64_t greater, uint32_t& misses) {
  const uint32_t n[kModes] = {uint32_t(std::popcount(high)), uint32_t(std::popcount(high ^ less)),
                              uint32_t(std::popcount(high ^ greater))};
  uint32_t mode = kModeNone;
  for (uint32_t m = 1; m < kModes; ++m)
    if (n[m] < n[mode]) mode = m;
  misses = n[mode];
  return mode;
}

struct Streams {
  std::vector<uint8_t> kinds, indices, palettes, planes, labels;
  uint32_t nodes = 0;
  bool predict = false;  // STPL: labels stored against a prediction
  void node(uint8_t kind) {
    if (nodes % 4 == 0) kinds.push_back(0);
    kinds.back() |= uint8_t(kind << (2 * (nodes % 4)));
    ++nodes;
  }
  void index(uint32_t i, bool wide) {
    indices.push_back(uint8_t(i));
    if (wide) indices.push_back(uint8_t(i >> 8));
  }
};

// Emits the quadtree node of Morton code `start` and side 2^s over the sorted, disjoint
// records from `next` on; false if a record does not sit on a node (not a valid tile).
bool emit_node(const PlaneTileView& v, uint64_t start, uint32_t s, uint32_t& next, Streams& out) {
  using namespace planes;
  const uint64_t end = start + (uint64_t(1) << (2 * s));
  if (next >= v.plane_count || v.block_start(next) >= end) {
    out.node(kNodeEmpty);
    return true;
  }
  if (v.block_start(next) == start && v.block_shift(next) == s) {
    const uint8_t* r = v.records.data() + size_t(next) * kRecordSize;
    const uint32_t index = load_le<uint16_t>(r + kOffIndex);
    ++next;
    if (r[kOffKind] == kKindPlane) {
      out.node(kNodePlane);
      out.index(index, v.table_count > 256);
      return true;
    }
    out.node(kNodeLabels);
    const uint8_t* l = v.labels.data() + size_t(index) * kLabelSize;
    if (r[kOffKind] == kKindWide) {  // as stored: 8 entries, 24 label bytes
      out.palettes.push_back(0);
      out.palettes.push_back(kWideUse);
      for (uint32_t k = 0; k < kWidePalette; ++k) {
        const uint32_t e = load_le<uint16_t>(l + 2 * k);
        out.planes.push_back(uint8_t(e));
        if (v.table_count > 256) out.planes.push_back(uint8_t(e >> 8));
      }
      out.labels.insert(out.labels.end(), l + kOffWideBits, l + kOffWidePad);
      return true;
    }
    uint32_t palette[kPalette], distinct[kPalette], n = 0, classes = 0;
    for (uint32_t k = 0; k < kPalette; ++k) {
      palette[k] = load_le<uint16_t>(l + 2 * k);
      uint32_t c = 0;
      while (c < n && distinct[c] != palette[k]) ++c;
      if (c == n) distinct[n++] = palette[k];
      classes |= c << (2 * k);
    }
    const uint8_t* bits = l + kOffLabelBits;
    const uint32_t used = used_entries(bits);
    out.palettes.push_back(uint8_t(classes));
    out.palettes.push_back(uint8_t(used));
    for (uint32_t c = 0; c < n; ++c) {
      out.planes.push_back(uint8_t(distinct[c]));
      if (v.table_count > 256) out.planes.push_back(uint8_t(distinct[c] >> 8));
    }
    if (out.predict && std::popcount(used) == 2) {
      const uint32_t low = uint32_t(std::countr_zero(used)), high = 31 - uint32_t(std::countl_zero(used));
      uint64_t word = 0, less = 0, greater = 0;
      for (uint32_t i = 0; i < kTexels; ++i) word |= uint64_t(label_of(bits, i) == high) << i;
      predict_two(v.table.data(), palette[low], palette[high], morton_compact(start), morton_compact(start >> 1), less, greater);
      uint32_t misses = 0;
      const uint32_t mode = best_mode_two(word, less, greater, misses);
      const uint64_t res = word ^ (mode == kModeLeast ? less : mode == kModeGreatest ? greater : 0);
      out.palettes.back() |= uint8_t(mode << kModeShift | (mode != kModeNone && misses == 0 ? kAllPredicted : 0));
      if (mode == kModeNone || misses != 0)
        for (uint32_t k = 0; k < kOneBitLabelBytes; ++k) out.labels.push_back(uint8_t(res >> (8 * k)));
    } else if (out.predict && std::popcount(used) > 2) {
      uint8_t lab[kTexels], res[kLabelBytes];
      for (uint32_t i = 0; i < kTexels; ++i) lab[i] = uint8_t(label_of(bits, i));
      const uint32_t x0 = morton_compact(start), y0 = morton_compact(start >> 1);
      Predictions pred;
      predict_labels(v.table.data(), palette, used, x0, y0, pred);
      uint32_t misses = 0;
      const uint32_t mode = best_mode(pred, lab, misses);
      residual(lab, pred.label[mode], used, res);
      if (mode != kModeNone && misses == 0) {
        out.palettes.back() |= uint8_t(mode << kModeShift | kAllPredicted);
      } else {
        out.palettes.back() |= uint8_t(mode << kModeShift);
        out.labels.insert(out.labels.end(), res, res + (std::popcount(used) == 2 ? kOneBitLabelBytes : kLabelBytes));
      }
    } else if (std::popcount(used) == 2) {
      const uint32_t high = 31 - uint32_t(std::countl_zero(used));
      uint64_t word = 0;
      for (uint32_t i = 0; i < kTexels; ++i) word |= uint64_t(label_of(bits, i) == high) << i;
      for (uint32_t k = 0; k < kOneBitLabelBytes; ++k) out.labels.push_back(uint8_t(word >> (8 * k)));
    } else if (std::popcount(used) > 2) {
      out.labels.insert(out.labels.end(), bits, bits + kLabelBytes);
    }
    return true;
  }
  if (s <= kMinShift) return false;
  out.node(kNodeSplit);
  for (uint64_t k = 0; k < 4; ++k)
    if (!emit_node(v, start + k * (uint64_t(1) << (2 * (s - 1))), s - 1, next, out)) return false;
  return true;
}

// Reads the packed streams of one buffer (bounds-checked, offsets in the whole buffer).
class Reader {
 public:
  Reader(const std::vector<uint8_t>& bytes, size_t base) : b_(bytes), base_(base) {}
  uint8_t byte(const char* field) {
    if (at_ >= b_.size()) fail(field, base_ + at_, "past the packed section");
    return b_[at_++];
  }
  uint32_t index(const char* field, bool wide) {
    uint32_t i = byte(field);
    if (wide) i |= uint32_t(byte(field)) << 8;
    return i;
  }
  uint8_t node() {
    if (bit_ == 0) cur_ = byte("block kinds");
    const uint8_t k = (cur_ >> bit_) & 3u;
    bit_ = (bit_ + 2) % 8;
    return k;
  }
  // The kinds stream ends on a byte: its unused high bits must be zero.
  void end_nodes() {
    if (bit_ != 0 && (cur_ >> bit_) != 0) fail("block kinds", base_ + at_ - 1, "stray bits after the last node");
    bit_ = 0;
  }
  size_t at() const { return base_ + at_; }
  size_t offset() const { return at_; }

 private:
  const std::vector<uint8_t>& b_;
  size_t base_ = 0, at_ = 0;
  uint32_t bit_ = 0;
  uint8_t cur_ = 0;
};

struct Block {
  uint32_t start = 0;
  uint8_t shift = 0, kind = 0;
};

// The node of Morton code `start` and side 2^s; returns whether it holds a block.
bool read_node(Reader& r, uint64_t start, uint32_t s, uint32_t max_blocks, std::vector<Block>& out) {
  using namespace planes;
  const size_t at = r.at();
  const uint8_t k = r.node();
  if (k == kNodeEmpty) return false;
  if (k != kNodeSplit) {
    if (k == kNodePlane && (s < kMinShift || s > kMaxShift))
      fail("block kinds", at, "a plane block of side 2^" + std::to_string(s));
    if (k == kNodeLabels && s != kLabelShift) fail("block kinds", at, "a labelled block of side 2^" + std::to_string(s));
    if (out.size() >= max_blocks) fail("block kinds", at, "more blocks than block_count " + std::to_string(max_blocks));
    out.push_back(Block{uint32_t(start), uint8_t(s), k == kNodePlane ? kKindPlane : kKindLabels});
    return true;
  }
  if (s <= kMinShift) fail("block kinds", at, "a split below side 2^" + std::to_string(kMinShift));
  bool any = false;
  for (uint64_t c = 0; c < 4; ++c) any |= read_node(r, start + c * (uint64_t(1) << (2 * (s - 1))), s - 1, max_blocks, out);
  if (!any) fail("block kinds", at, "a split with no block below it");
  return true;
}

void unpack(std::span<uint8_t> b);

std::vector<uint8_t> pack(std::span<const uint8_t> stpn, PlanePackParts* parts, bool predict) {
  PlaneTileView v;
  try {
    v = validate_plane_tile(stpn);
  } catch (const FormatError&) {
    return {};
  }
  Streams s;
  s.predict = predict;
  uint32_t next = 0;
  if (!emit_node(v, 0, v.finest_level, next, s) || next != v.plane_count) return {};
  const size_t table_end = planes::kHeaderSize + v.table.size();
  const size_t inner_at = size_t(v.inner.data() - stpn.data());
  const size_t packed = s.kinds.size() + s.indices.size() + s.palettes.size() + s.planes.size() + s.labels.size();
  if (table_end + packed > inner_at) return {};
  std::vector<uint8_t> out(stpn.begin(), stpn.end());
  store_le<uint32_t>(out.data(), predict ? plane_pack::kMagicPredicted : plane_pack::kMagic);
  uint8_t* p = out.data() + table_end;
  for (const std::vector<uint8_t>* part : {&s.kinds, &s.indices, &s.palettes, &s.planes, &s.labels}) {
    if (!part->empty()) std::memcpy(p, part->data(), part->size());
    p += part->size();
  }
  std::fill(p, out.data() + inner_at, uint8_t(0));
  if (predict) {  // STPL: the inner MH/MMH header's derivable fields left out (zeros)
    const uint32_t kind = inner_kind(v.inner, v.finest_level + 1);
    out[planes::kOffFlags] = uint8_t(kind);
    if (kind != kInnerKept)
      for (const auto& [from, to] : kInnerLeftOut) std::fill(out.data() + inner_at + from, out.data() + inner_at + to, uint8_t(0));
  }
  // The form is only kept if it unpacks to the very bytes it came from.
  std::vector<uint8_t> back = out;
  try {
    unpack(back);
  } catch (const FormatError&) {
    return {};
  }
  if (!std::equal(back.begin(), back.end(), stpn.begin(), stpn.end())) return {};
  if (parts) *parts = {s.kinds.size(), s.indices.size(), s.palettes.size(), s.planes.size(), s.labels.size()};
  return out;
}

void unpack(std::span<uint8_t> b) {
  using namespace planes;
  if (b.size() < kHeaderSize) fail("header", 0, std::to_string(b.size()) + " bytes, fewer than 24");
  const uint32_t magic = load_le<uint32_t>(b.data());
  if (magic != plane_pack::kMagic && magic != plane_pack::kMagicPredicted) fail("magic", 0, "not \"STPQ\" or \"STPL\"");
  const bool predicted = magic == plane_pack::kMagicPredicted;
  const uint32_t levels = b[kOffLevels];
  if (levels < 1 || levels > kMaxLevels) fail("levels", kOffLevels, std::to_string(levels) + " outside 1..17");
  const uint32_t count = load_le<uint32_t>(b.data() + kOffPlaneCount);
  const uint32_t tables = load_le<uint32_t>(b.data() + kOffTableCount);
  const uint32_t label_count = load_le<uint32_t>(b.data() + kOffLabelCount);
  if (count > kMaxPlanes) fail("block_count", kOffPlaneCount, std::to_string(count) + " above 2^20");
  if (tables > kMaxTable) fail("table_count", kOffTableCount, std::to_string(tables) + " above 65535");
  if (label_count > uint64_t(kWideSlots) * count)
    fail("label_count", kOffLabelCount, std::to_string(label_count) + " above 2 block_count");
  const size_t table_end = kHeaderSize + size_t(tables) * kEntrySize;
  const size_t labels_at = table_end + size_t(count) * kRecordSize;
  const size_t inner_at = labels_at + size_t(label_count) * kLabelSize;
  if (inner_at > b.size())
    fail("block_count", kOffPlaneCount, "the unpacked blocks end at byte " + std::to_string(inner_at) + ", past the " +
                                            std::to_string(b.size()) + "-byte buffer");
  const std::vector<uint8_t> packed(b.begin() + ptrdiff_t(table_end), b.begin() + ptrdiff_t(inner_at));
  Reader r(packed, table_end);
  const size_t kinds_at = r.at();
  std::vector<Block> blocks;
  blocks.reserve(count);
  read_node(r, 0, levels - 1, count, blocks);
  r.end_nodes();
  if (blocks.size() != count)
    fail("block kinds", kinds_at, std::to_string(blocks.size()) + " blocks, block_count says " + std::to_string(count));
  const bool wide = tables > 256;
  std::vector<uint16_t> index(count);
  std::vector<uint32_t> label_start, label_block;  // each labelled block's start and block number, in order
  for (uint32_t i = 0; i < count; ++i) {
    if (blocks[i].kind == kKindPlane) {
      index[i] = uint16_t(r.index("plane index", wide));
    } else {
      label_block.push_back(i);
      label_start.push_back(blocks[i].start);
    }
  }
  const uint32_t labelled = uint32_t(label_start.size());
  if (labelled > label_count)
    fail("block kinds", kinds_at, std::to_string(labelled) + " labelled blocks, label_count says " + std::to_string(label_count) + " slots");
  std::vector<uint8_t> palettes(2 * size_t(labelled));
  for (uint8_t& p : palettes) p = r.byte("palettes");
  // Each labelled block's first slot (a wide one takes two), in record order.
  std::vector<uint32_t> slot(labelled);
  uint32_t slots = 0;
  for (uint32_t j = 0; j < labelled; ++j) {
    const bool is_wide = palettes[2 * j + 1] == kWideUse;
    slot[j] = slots;
    slots += is_wide ? kWideSlots : 1;
    if (slots <= label_count) {
      index[label_block[j]] = uint16_t(slot[j]);
      blocks[label_block[j]].kind = is_wide ? kKindWide : kKindLabels;
    }
  }
  if (slots != label_count)
    fail("block kinds", kinds_at, std::to_string(labelled) + " labelled blocks take " + std::to_string(slots) +
                                      " slots, label_count says " + std::to_string(label_count));
  auto is_wide = [&](uint32_t j) { return blocks[label_block[j]].kind == kKindWide; };
  std::vector<uint8_t> labels(size_t(label_count) * kLabelSize);
  std::vector<uint8_t> distinct_count(labelled);
  for (uint32_t j = 0; j < labelled; ++j) {
    const uint32_t classes = palettes[2 * j], used = palettes[2 * j + 1] & (predicted ? 0x0Fu : 0xFFu);
    const uint32_t mode = palettes[2 * j + 1] >> kModeShift & 3u, all = palettes[2 * j + 1] & kAllPredicted;
    const size_t at = r.at() - 2 * size_t(labelled - j);  // its palette bytes
    if (is_wide(j)) {
      if (classes != 0) fail("labelled block " + std::to_string(j) + " classes", at, "not zero in a wide block");
      continue;
    }
    uint32_t n = 0;
    for (uint32_t k = 0; k < kPalette; ++k) {
      const uint32_t c = (classes >> (2 * k)) & 3u;
      if (c > n) fail("labelled block " + std::to_string(j) + " classes", at, "not in first-seen order");
      n = std::max(n, c + 1);
    }
    if (used == 0 || used > 15) fail("labelled block " + std::to_string(j) + " use mask", at + 1, "not 1..15");
    if (predicted && (palettes[2 * j + 1] & 0x80u || mode >= kModes || (all && mode == kModeNone) ||
                      (std::popcount(used) < 2 && (mode != kModeNone || all))))
      fail("labelled block " + std::to_string(j) + " prediction", at + 1, "mode " + std::to_string(mode) + (all ? ", all predicted" : "") +
                                                                              " with " + std::to_string(std::popcount(used)) + " entries used");
    distinct_count[j] = uint8_t(n);
  }
  std::vector<uint32_t> entries(size_t(labelled) * kPalette);  // each block's palette as table indices
  for (uint32_t j = 0; j < labelled; ++j) {
    if (is_wide(j)) {  // its 8 entries as stored (the STPN validator checks them)
      uint8_t* l = labels.data() + size_t(slot[j]) * kLabelSize;
      for (uint32_t k = 0; k < kWidePalette; ++k) store_le<uint16_t>(l + 2 * k, uint16_t(r.index("palette planes", wide)));
      continue;
    }
    const uint32_t classes = palettes[2 * j];
    uint32_t distinct[kPalette] = {};
    for (uint32_t c = 0; c < distinct_count[j]; ++c) {
      const size_t at = r.at();
      distinct[c] = r.index("palette planes", wide);
      for (uint32_t d = 0; d < c; ++d)
        if (distinct[d] == distinct[c]) fail("labelled block " + std::to_string(j) + " planes", at, "a plane named twice");
      if (predicted && distinct[c] >= tables)
        fail("labelled block " + std::to_string(j) + " planes", at, "plane " + std::to_string(distinct[c]) + " of " + std::to_string(tables));
    }
    uint8_t* l = labels.data() + size_t(slot[j]) * kLabelSize;
    for (uint32_t k = 0; k < kPalette; ++k) {
      entries[size_t(j) * kPalette + k] = distinct[(classes >> (2 * k)) & 3u];
      store_le<uint16_t>(l + 2 * k, uint16_t(entries[size_t(j) * kPalette + k]));
    }
  }
  for (uint32_t j = 0; j < labelled; ++j) {
    const uint32_t used = palettes[2 * j + 1] & 0x0Fu;
    if (is_wide(j)) {  // its 24 label bytes as stored
      uint8_t* bits = labels.data() + size_t(slot[j]) * kLabelSize + kOffWideBits;
      for (size_t k = 0; k < kOffWidePad - kOffWideBits; ++k) bits[k] = r.byte("labels");
      continue;
    }
    uint8_t* bits = labels.data() + size_t(slot[j]) * kLabelSize + kOffLabelBits;
    const size_t at = r.at();
    if (predicted && std::popcount(used) == 2) {
      // One bit a texel against a two-plane prediction: undo it, check the mode is the writer's.
      const uint32_t mode = palettes[2 * j + 1] >> kModeShift & 3u;
      const bool all = palettes[2 * j + 1] & kAllPredicted;
      const uint32_t low = uint32_t(std::countr_zero(used)), high = 31 - uint32_t(std::countl_zero(used));
      const uint32_t* palette = entries.data() + size_t(j) * kPalette;
      uint64_t less = 0, greater = 0, res = 0;
      predict_two(b.data() + kHeaderSize, palette[low], palette[high], morton_compact(label_start[j]),
                  morton_compact(label_start[j] >> 1), less, greater);
      if (!all)
        for (uint32_t k = 0; k < kOneBitLabelBytes; ++k) res |= uint64_t(r.byte("labels")) << (8 * k);
      if (!all && res == 0 && mode != kModeNone)
        fail("labelled block " + std::to_string(j) + " labels", at, "all predicted, not flagged so");
      const uint64_t word = res ^ (mode == kModeLeast ? less : mode == kModeGreatest ? greater : 0);
      for (uint32_t k = 0; k < kOneBitLabelBytes; ++k) store_le<uint16_t>(bits + 2 * k, widen_labels(uint8_t(word >> (8 * k)), low, high));
      uint32_t misses = 0;
      if (used_entries(bits) == used && best_mode_two(word, less, greater, misses) != mode)
        fail("labelled block " + std::to_string(j) + " prediction", at, "mode " + std::to_string(mode) + " is not the one that predicts most");
    } else if (predicted && std::popcount(used) > 2) {
      // Labels stored against a prediction: undo it, then check the mode is the writer's.
      const uint32_t mode = palettes[2 * j + 1] >> kModeShift & 3u;
      const bool all = palettes[2 * j + 1] & kAllPredicted;
      const uint32_t* palette = entries.data() + size_t(j) * kPalette;
      const uint32_t x0 = morton_compact(label_start[j]), y0 = morton_compact(label_start[j] >> 1);
      const uint8_t* table = b.data() + kHeaderSize;
      uint8_t lab[kTexels], res[kLabelBytes] = {};
      Predictions predictions;
      predict_labels(table, palette, used, x0, y0, predictions);
      const uint8_t* pred = predictions.label[mode < kModes ? mode : kModeNone];
      const bool two = std::popcount(used) == 2;
      if (!all)
        for (size_t k = 0; k < (two ? kOneBitLabelBytes : kLabelBytes); ++k) res[k] = r.byte("labels");
      const uint32_t low = uint32_t(std::countr_zero(used)), high = 31 - uint32_t(std::countl_zero(used));
      bool any = false;
      for (uint32_t i = 0; i < kTexels; ++i) {
        const uint32_t rb = two ? (res[i / 8] >> (i % 8)) & 1u : (res[i / 4] >> (2 * (i % 4))) & 3u;
        any |= rb != 0;
        lab[i] = uint8_t(two ? ((rb != 0) != (pred[i] == high) ? high : low) : (pred[i] ^ rb));
      }
      if (!all && any == false && mode != kModeNone)
        fail("labelled block " + std::to_string(j) + " labels", at, "all predicted, not flagged so");
      std::fill(bits, bits + kLabelBytes, uint8_t(0));
      for (uint32_t i = 0; i < kTexels; ++i) bits[i / 4] |= uint8_t(lab[i] << (2 * (i % 4)));
      uint32_t misses = 0;
      if (used_entries(bits) == used && best_mode(predictions, lab, misses) != mode)
        fail("labelled block " + std::to_string(j) + " prediction", at, "mode " + std::to_string(mode) + " is not the one that predicts most");
    } else if (std::popcount(used) == 1) {
      const uint32_t e = uint32_t(std::countr_zero(used));
      std::fill(bits, bits + kLabelBytes, uint8_t(e | e << 2 | e << 4 | e << 6));
    } else if (std::popcount(used) == 2) {
      const uint32_t low = uint32_t(std::countr_zero(used)), high = 31 - uint32_t(std::countl_zero(used));
      for (uint32_t k = 0; k < kOneBitLabelBytes; ++k) store_le<uint16_t>(bits + 2 * k, widen_labels(r.byte("labels"), low, high));
    } else {
      for (size_t k = 0; k < kLabelBytes; ++k) bits[k] = r.byte("labels");
    }
    if (used_entries(bits) != used)
      fail("labelled block " + std::to_string(j) + " use mask", at, "not the entries its labels use");
  }
  for (size_t k = r.offset(); k < packed.size(); ++k)
    if (packed[k] != 0) fail("padding", table_end + k, "not zero");
  if (predicted) {
    // The inner MH/MMH header's derivable fields, left out (zeros) by the kind in byte 7.
    const uint32_t kind = b[kOffFlags];
    std::span<uint8_t> inner = b.subspan(inner_at);
    if (kind > kInnerMmh) fail("inner kind", kOffFlags, std::to_string(kind) + " not 0..2");
    if (kind == kInnerKept) {
      if (inner_kind(inner, levels) != kInnerKept)
        fail("inner kind", kOffFlags, "0 for an MH or MMH inner buffer whose header could be left out");
    } else {
      if (inner.size() < mhq::kHeaderFixedSize) fail("inner header", inner_at, "shorter than 16 bytes");
      for (const auto& [from, to] : kInnerLeftOut)
        for (size_t k = from; k < to; ++k)
          if (inner[k] != 0) fail("inner header", inner_at + k, "a left-out byte not zero");
      store_le<uint32_t>(inner.data(), kind == kInnerMh ? mhq::kMagicMh : mhq::kMagicMmh);
      store_le<uint16_t>(inner.data() + mhq::kOffVersion, mhq::kVersion);
      inner[mhq::kOffLevels] = uint8_t(levels);
      store_le<uint32_t>(inner.data() + mhq::kOffByteSize, uint32_t(inner.size()));
    }
    b[kOffFlags] = 0;
  }
  store_le<uint32_t>(b.data(), planes::kMagic);
  for (uint32_t i = 0; i < count; ++i) {
    uint8_t* rec = b.data() + table_end + size_t(i) * kRecordSize;
    store_le<uint32_t>(rec + kOffStart, blocks[i].start);
    rec[kOffShift] = blocks[i].shift;
    rec[kOffKind] = blocks[i].kind;
    store_le<uint16_t>(rec + kOffIndex, index[i]);
  }
  if (!labels.empty()) std::memcpy(b.data() + labels_at, labels.data(), labels.size());
}

}  // namespace plane_pack

bool is_packed_plane_tile(std::span<const uint8_t> bytes) {
  if (bytes.size() < 4) return false;
  const uint32_t magic = load_le<uint32_t>(bytes.data());
  return magic == plane_pack::kMagic || magic == plane_pack::kMagicPredicted;
}

uint32_t packed_plane_tile_features(std::span<const uint8_t> bytes) {
  if (!is_packed_plane_tile(bytes)) return 0;
  return load_le<uint32_t>(bytes.data()) == plane_pack::kMagicPredicted ? kFeaturePackedPlaneTiles | kFeaturePredictedPlaneLabels
                                                                        : kFeaturePackedPlaneTiles;
}

uint32_t plane_tile_features(std::span<const uint8_t> bytes) {
  if (!is_plane_buffer(bytes) && !is_packed_plane_tile(bytes)) return 0;
  const bool wide = bytes.size() >= 6 && load_le<uint16_t>(bytes.data() + 4) > planes::kVersionNarrow;
  return packed_plane_tile_features(bytes) | (wide ? uint32_t(kFeatureWidePlaneBlocks) : 0);
}

std::vector<uint8_t> pack_plane_tile(std::span<const uint8_t> stpn, PlanePackParts* parts, bool predict_labels) {
  return plane_pack::pack(stpn, parts, predict_labels);
}

void unpack_plane_tile(std::span<uint8_t> bytes) { plane_pack::unpack(bytes); }

}  // namespace st
