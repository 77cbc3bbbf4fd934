#include "tiles/core/plane_tile.hpp"

#include <algorithm>
#include <string>

#include "common/bytes.hpp"
#include "common/error.hpp"
#include "tiles/core/morton.hpp"
#include "tiles/core/receiver_plane.hpp"
#include "tiles/core/tap_batch.hpp"

namespace st {

namespace {

using namespace planes;

[[noreturn]] void fail(const std::string& field, size_t offset, const std::string& why) {
  throw FormatError("plane tile: " + field + " at byte " + std::to_string(offset) + ": " + why);
}

int64_t abs64(int64_t v) { return v < 0 ? (v == INT64_MIN ? INT64_MAX : -v) : v; }

class PlaneTileEvaluator final : public Evaluator, public TapWalks {
 public:
  PlaneTileEvaluator(PlaneTileView view, std::unique_ptr<Evaluator> inner)
      : v_(view), inner_(std::move(inner)), inner_walks_(dynamic_cast<const TapWalks*>(inner_.get())) {}

  uint32_t finest_level() const override { return v_.finest_level; }

  float depth(uint32_t level, uint64_t x, uint64_t y) const override {
    float d;
    return from_plane(level, x, y, d) ? d : inner_->depth(level, x, y);
  }

  DepthRegion depth_region(uint32_t level, uint64_t x, uint64_t y) const override {
    float d;
    if (from_plane(level, x, y, d)) return {d, 0};
    // The inner walk's region may cover a plane block (a node with nothing valued below
    // it after the blocks were taken out): it is only the texel's own then.
    return inner_region(level, x, y, inner_->depth_region(level, x, y));
  }

  // TapWalks (tap_batch.hpp): depth_region's answers, the inner tree's walks resumed from
  // the caller's path.
  DepthRegion walk_tap(uint32_t level, uint64_t x, uint64_t y, TapPath& path) const noexcept override {
    float d;
    if (from_plane(level, x, y, d)) return {d, 0};
    return inner_region(level, x, y, inner_walk(level, x, y, path));
  }
  // A run of taps (in Morton order when the client sorted them): the block of the last
  // tap answers the next one inside it without a search, and the search for another
  // starts from it (the blocks are sorted by Morton code); the other taps walk the inner
  // tree from its last walk's path. The same answers as depth_region, tap for tap.
  TapRunEnd tap_run(const TapRun& run, TapPath& path) const noexcept override;
  // The block records, the plane table and the inner tree, which a run's searches and
  // walks read first (WindowDepths::prefetch's role, for the client's next tile).
  // Only their first lines: a prefetch per line of every record (kilobytes in a tile of
  // many blocks) stalled the lookups more than it saved (perf: ~10% of a real level's
  // taps), and a level's tiles mostly stay in the cache between frames.
  void prefetch() const noexcept override {
    __builtin_prefetch(v_.records.data());
    __builtin_prefetch(v_.table.data());
    __builtin_prefetch(v_.inner.data());
  }

  float pcf(uint32_t level, uint64_t x, uint64_t y, uint32_t r, float receiver) const override {
    // The kernel's square at the finest level: no block in it, the inner walk shares it.
    r = std::clamp<uint32_t>(r, 1, kMaxPcf);
    const uint64_t side = uint64_t(1) << level;
    const uint64_t x0 = pcf_tap(x, 0, r, side), y0 = pcf_tap(y, 0, r, side);
    const uint64_t x1 = pcf_tap(x, r - 1, r, side), y1 = pcf_tap(y, r - 1, r, side);
    uint32_t blocks[kPcfBlocks];
    const uint32_t n = blocks_in_rect(level, x0, y0, x1, y1, blocks);
    if (n == 0) return inner_->pcf(level, x, y, r, receiver);
    if (n > kPcfBlocks) return Evaluator::pcf(level, x, y, r, receiver);
    return count_with_blocks(level, x, y, r, blocks, n, [receiver](uint64_t, uint64_t) { return receiver; });
  }

  // pcf's scheme with each tap against the receiver plane (receiver_plane.hpp): no block
  // under the kernel, the inner tree's own pcf_on_plane (its shared walk).
  float pcf_on_plane(uint32_t level, uint64_t x, uint64_t y, uint32_t r, const ReceiverPlane& p) const override {
    r = std::clamp<uint32_t>(r, 1, kMaxPcf);
    const uint64_t side = uint64_t(1) << level;
    const uint64_t x0 = pcf_tap(x, 0, r, side), y0 = pcf_tap(y, 0, r, side);
    const uint64_t x1 = pcf_tap(x, r - 1, r, side), y1 = pcf_tap(y, r - 1, r, side);
    uint32_t blocks[kPcfBlocks];
    const uint32_t n = blocks_in_rect(level, x0, y0, x1, y1, blocks);
    if (n == 0) return inner_->pcf_on_plane(level, x, y, r, p);
    if (n > kPcfBlocks) return pcf_plane_by_taps(*this, level, x, y, r, p);
    return count_with_blocks(level, x, y, r, blocks, n,
                             [&p, level](uint64_t tx, uint64_t ty) { return receiver_plane_depth(p, level, tx, ty); });
  }

 private:
  // The few blocks the kernel meets, found once: each tap tests them (no search of its own,
  // from_plane's answer), the taps none holds ask the inner buffer; `receiver_at(tx, ty)` is
  // the depth each tap compares (one receiver, or the receiver plane's over that texel).
  template <class ReceiverAt>
  float count_with_blocks(uint32_t level, uint64_t x, uint64_t y, uint32_t r, const uint32_t* blocks, uint32_t n,
                          ReceiverAt receiver_at) const {
    const uint64_t side = uint64_t(1) << level;
    const uint32_t s = v_.finest_level - level;
    const uint64_t h = s ? uint64_t(1) << (s - 1) : 0;
    uint32_t lit_taps = 0;
    for (uint32_t j = 0; j < r; ++j) {
      const uint64_t ty = pcf_tap(y, j, r, side);
      const uint32_t fy = uint32_t((ty << s) + h);
      for (uint32_t i = 0; i < r; ++i) {
        const uint64_t tx = pcf_tap(x, i, r, side);
        const uint32_t fx = uint32_t((tx << s) + h);
        float d;
        if (!tap_plane(blocks, n, s, fx, fy, d)) d = inner_->depth(level, tx, ty);
        lit_taps += receiver_at(tx, ty) <= d;
      }
    }
    return float(lit_taps) / float(r * r);
  }

  bool from_plane(uint32_t level, uint64_t x, uint64_t y, float& out) const {
    const uint32_t s = v_.finest_level - level;
    if (s >= kMaxShift) return false;  // no block is as coarse as this texel
    const uint64_t h = s ? uint64_t(1) << (s - 1) : 0;
    const uint32_t fx = uint32_t((x << s) + h), fy = uint32_t((y << s) + h);
    const int64_t i = v_.find(fx, fy);
    if (i < 0) return false;
    const Plane p = v_.plane_at(uint32_t(i), fx, fy);
    if (p.shift <= s) return false;  // the block is finer than the texel
    const uint32_t mask = (uint32_t(1) << p.shift) - 1;
    out = p.depth(fx & mask, fy & mask);
    return true;
  }

  static constexpr uint32_t kPcfBlocks = 16;

  // from_plane for the finest texel (fx, fy) under a texel of level finest - s, looked up in
  // `blocks` (every block that can hold it).
  bool tap_plane(const uint32_t* blocks, uint32_t n, uint32_t s, uint32_t fx, uint32_t fy, float& out) const {
    if (s >= kMaxShift) return false;
    for (uint32_t k = 0; k < n; ++k) {
      const uint32_t start = v_.block_start(blocks[k]), shift = v_.block_shift(blocks[k]);
      const uint32_t bx = morton_compact(start), by = morton_compact(uint64_t(start) >> 1);
      if (fx - bx >= (1u << shift) || fy - by >= (1u << shift)) continue;  // unsigned: fx < bx too
      if (shift <= s) return false;  // the block is finer than the texel
      const Plane p = v_.plane_at(blocks[k], fx, fy);
      const uint32_t mask = (uint32_t(1) << p.shift) - 1;
      out = p.depth(fx & mask, fy & mask);
      return true;
    }
    return false;
  }

  // Whether any block meets the finest-level rectangle under texels [x0, x1] x [y0, y1] of `level`.
  bool overlaps_rect(uint32_t level, uint64_t x0, uint64_t y0, uint64_t x1, uint64_t y1) const {
    uint32_t none[1];
    return blocks_in_rect(level, x0, y0, x1, y1, none, 0) > 0;
  }
  // The blocks meeting that rectangle, in `out` (at most `cap`); returns their count, or
  // cap + 1 when there are more.
  uint32_t blocks_in_rect(uint32_t level, uint64_t x0, uint64_t y0, uint64_t x1, uint64_t y1, uint32_t* out,
                          uint32_t cap = kPcfBlocks) const {
    const uint32_t s = v_.finest_level - level;
    const uint64_t fx0 = x0 << s, fy0 = y0 << s, fx1 = ((x1 + 1) << s) - 1, fy1 = ((y1 + 1) << s) - 1;
    // Every texel of the rectangle has a morton code in [m0, m1] (the code grows with x and
    // with y): only blocks whose codes meet that range can meet it.
    const uint64_t m0 = morton_encode(uint32_t(fx0), uint32_t(fy0)), m1 = morton_encode(uint32_t(fx1), uint32_t(fy1));
    uint32_t i = 0, hi = v_.plane_count, count = 0;
    while (i < hi) {  // the first block ending after m0
      const uint32_t mid = (i + hi) / 2;
      if (v_.block_end(mid) <= m0) i = mid + 1;
      else hi = mid;
    }
    for (; i < v_.plane_count; ++i) {
      const uint32_t start = v_.block_start(i);
      if (start > m1) break;
      const uint64_t bx = morton_compact(start), by = morton_compact(uint64_t(start) >> 1);
      const uint64_t side = uint64_t(1) << v_.block_shift(i);
      if (bx <= fx1 && fx0 < bx + side && by <= fy1 && fy0 < by + side) {
        if (count == cap) return cap + 1;
        out[count++] = i;
      }
    }
    return count;
  }
  bool overlaps_plane(uint32_t level, uint64_t x, uint64_t y, uint32_t shift) const {
    const uint64_t n = (uint64_t(1) << shift) - 1;
    return overlaps_rect(level, x, y, x + n, y + n);
  }

  // The inner tree's answer with depth_region's rule: a region over a plane block is the
  // texel's own.
  DepthRegion inner_region(uint32_t level, uint64_t x, uint64_t y, DepthRegion r) const {
    if (r.shift > 0 && overlaps_plane(level, x >> r.shift << r.shift, y >> r.shift << r.shift, r.shift)) r.shift = 0;
    return r;
  }
  DepthRegion inner_walk(uint32_t level, uint64_t x, uint64_t y, TapPath& path) const noexcept {
    if (inner_walks_) return inner_walks_->walk_tap(level, x, y, path);
    try {
      return inner_->depth_region(level, x, y);
    } catch (...) {  // an opened tile does not throw; if one did, stay lit and alive
      return DepthRegion{1.0f, 0};
    }
  }

  // tap_run's block: the one holding the last tap's finest texel, or none (bx = by =
  // ~0, shift 0: no texel matches). Corner and side at the finest level; a one-plane
  // block's table plane (a at the tile's texel (0, 0): a + b fx + c fy is the same integer
  // modulo 2^64 as plane_at's corner form), or a labelled block's palette and labels.
  struct TapBlock {
    uint64_t x = ~uint64_t(0), y = ~uint64_t(0);
    uint32_t index = 0, shift = 0;
    const uint8_t* labels = nullptr;
    bool wide = false;  // labels: a wide labelled block's
    uint64_t a = 0, b = 0, c = 0;
  };
  // The block holding finest texel (fx, fy), searched outward from b.index (the last
  // block starting at or before its Morton code: find's answer, in fewer steps for a
  // sorted run). Out of line: taps in the last block do not pay its registers.
  [[gnu::noinline]] void find_tap_block(uint64_t fx, uint64_t fy, TapBlock& b) const noexcept;

  PlaneTileView v_;
  std::unique_ptr<Evaluator> inner_;
  const TapWalks* inner_walks_;  // the inner tree's resumable walks, or null
};

void PlaneTileEvaluator::find_tap_block(uint64_t fx, uint64_t fy, TapBlock& blk) const noexcept {
  const uint32_t count = v_.plane_count;
  // The records read here, inline (PlaneTileView's readers are out of line: a call per
  // probe of the search showed in a real level's profile).
  const uint8_t* const records = v_.records.data();
  auto start_of = [records](uint32_t i) { return load_le<uint32_t>(records + size_t(i) * kRecordSize + kOffStart); };
  const uint64_t m = morton_encode(uint32_t(fx), uint32_t(fy));
  const uint32_t bi = blk.index;
  uint32_t lo, hi;  // the first block starting after m lies in [lo, hi]
  if (start_of(bi) <= m) {
    uint32_t a = bi, step = 1;  // start(a) <= m
    while (a + step < count && start_of(a + step) <= m) a += step, step *= 2;
    lo = a + 1, hi = uint32_t(std::min<uint64_t>(count, uint64_t(a) + step));
  } else {
    uint32_t b = bi, step = 1;  // start(b) > m
    while (b >= step && start_of(b - step) > m) b -= step, step *= 2;
    lo = b >= step ? b - step + 1 : 0, hi = b;
  }
  while (lo < hi) {  // PlaneTileView::first_block_after
    const uint32_t mid = lo + (hi - lo) / 2;
    if (start_of(mid) <= m) lo = mid + 1;
    else hi = mid;
  }
  blk.x = blk.y = ~uint64_t(0), blk.shift = 0;
  if (lo == 0) return;
  const uint32_t j = lo - 1;
  blk.index = j;
  const uint8_t* b = records + size_t(j) * kRecordSize;
  const uint32_t start = start_of(j), shift = b[kOffShift];
  if (m >= uint64_t(start) + (uint64_t(1) << (2 * shift))) return;  // past the block's end (block_end)
  blk.x = morton_compact(start), blk.y = morton_compact(uint64_t(start) >> 1), blk.shift = shift;
  const uint32_t index = load_le<uint16_t>(b + kOffIndex);
  if (b[kOffKind] != kKindPlane) {
    blk.labels = v_.labels.data() + size_t(index) * kLabelSize;
    blk.wide = b[kOffKind] == kKindWide;
  } else {
    const uint8_t* e = v_.table.data() + size_t(index) * kEntrySize;
    blk.labels = nullptr;
    blk.a = load_le<uint64_t>(e + kOffA), blk.b = load_le<uint64_t>(e + kOffB), blk.c = load_le<uint64_t>(e + kOffC);
  }
}

TapRunEnd PlaneTileEvaluator::tap_run(const TapRun& run, TapPath& path) const noexcept {
  const uint32_t s = v_.finest_level - std::min(run.rel, v_.finest_level);
  if (s >= kMaxShift)  // no block is as coarse as these texels: every tap asks the inner tree
    return tap_run_loop(run, [&](uint32_t l, uint64_t x, uint64_t y) { return inner_region(l, x, y, inner_walk(l, x, y, path)); });
  const uint64_t top = (uint64_t(1) << run.level) - 1;
  const uint64_t h = s ? uint64_t(1) << (s - 1) : 0;
  const uint8_t* const table = v_.table.data();
  const PcfQuery* const queries = run.queries;
  const uint16_t* const order = run.order;
  float* const out = run.out;
  const uint64_t x0 = run.x0, y0 = run.y0;
  const size_t n = run.count;
  // The last answer, in registers: its texel and region; `kept` when that region is the
  // inner tree's, which may hold the next taps (a plane's answer holds its own texel only).
  uint64_t ex = 0, ey = 0, walks = 0;
  DepthRegion er{0, 0};
  bool kept = false;
  // The block of the last tap (TapBlock's fields in locals, so that they stay in
  // registers: find_tap_block's TapBlock lives in memory).
  uint64_t bx = ~uint64_t(0), by = ~uint64_t(0), pa = 0, pb = 0, pc = 0;
  uint32_t bshift = 0, bindex = 0;
  const uint8_t* blabels = nullptr;
  bool bwide = false;
  size_t k = 0;
  for (; k < n; ++k) {
    const uint32_t i = order[k];
    const PcfQuery& q = queries[i];
    const uint64_t x = std::min(q.x, top) - x0, y = std::min(q.y, top) - y0;
    if (run.ends(q, x, y)) [[unlikely]]
      break;
    if (kept && (((x ^ ex) | (y ^ ey)) >> er.shift) == 0) {
      out[i] = tap_lit(q.receiver, er.value);
      continue;
    }
    ++walks;
    const uint64_t fx = (x << s) + h, fy = (y << s) + h;
    if (((fx ^ bx) | (fy ^ by)) >> bshift != 0) [[unlikely]] {
      TapBlock blk;
      blk.index = bindex;
      find_tap_block(fx, fy, blk);
      bx = blk.x, by = blk.y, bshift = blk.shift, bindex = blk.index;
      blabels = blk.labels, bwide = blk.wide, pa = blk.a, pb = blk.b, pc = blk.c;
    }
    if (bshift > s) {  // from_plane: a block coarser than the texel answers it
      uint64_t a = pa, b = pb, c = pc;
      if (blabels) [[unlikely]] {  // plane_at's label: the texel's 2 (3) bits, then its palette entry
        const uint32_t t = uint32_t(((fy - by) << kLabelShift) + (fx - bx));
        const uint32_t label =
            bwide ? wide_label(blabels + kOffWideBits, t) : (blabels[kOffLabelBits + t / 4] >> (2 * (t % 4))) & 3u;
        const uint8_t* e = table + size_t(load_le<uint16_t>(blabels + 2 * label)) * kEntrySize;
        a = load_le<uint64_t>(e + kOffA), b = load_le<uint64_t>(e + kOffB), c = load_le<uint64_t>(e + kOffC);
      }
      er = {plane_fixed_to_float_cpu(int64_t(a + b * fx + c * fy)), 0};
      kept = false;
    } else {
      er = inner_region(run.rel, x, y, inner_walk(run.rel, x, y, path));
      kept = true;
    }
    ex = x, ey = y;
    out[i] = tap_lit(q.receiver, er.value);
  }
  TapRunEnd end;
  end.x = ex, end.y = ey, end.region = er, end.walks = walks, end.count = k;
  return end;
}

}  // namespace

bool is_plane_buffer(std::span<const uint8_t> bytes) {
  return bytes.size() >= 4 && load_le<uint32_t>(bytes.data()) == kMagic;
}

Plane PlaneTileView::plane_at(uint32_t i, uint32_t fx, uint32_t fy) const {
  const uint8_t* r = records.data() + size_t(i) * kRecordSize;
  Plane p;
  p.start = load_le<uint32_t>(r + kOffStart);
  p.shift = r[kOffShift];
  const uint32_t x0 = morton_compact(p.start), y0 = morton_compact(uint64_t(p.start) >> 1);
  uint32_t entry = load_le<uint16_t>(r + kOffIndex);
  if (r[kOffKind] != kKindPlane) {  // a labelled block (validated: kKindLabels or kKindWide)
    const uint8_t* lb = labels.data() + size_t(entry) * kLabelSize;
    const uint32_t t = ((fy - y0) << kLabelShift) + (fx - x0);
    const uint32_t label = r[kOffKind] == kKindWide ? wide_label(lb + kOffWideBits, t)
                                                    : (lb[kOffLabelBits + t / 4] >> (2 * (t % 4))) & 3u;
    entry = load_le<uint16_t>(lb + 2 * label);
  }
  const uint8_t* e = table.data() + size_t(entry) * kEntrySize;
  p.b = int64_t(load_le<uint64_t>(e + kOffB));
  p.c = int64_t(load_le<uint64_t>(e + kOffC));
  // a' = a + b x0 + c y0 modulo 2^64 (plane_format.hpp).
  p.a = int64_t(load_le<uint64_t>(e + kOffA) + uint64_t(p.b) * x0 + uint64_t(p.c) * y0);
  return p;
}

Plane PlaneTileView::plane(uint32_t i) const {
  const uint32_t start = block_start(i);
  return plane_at(i, morton_compact(start), morton_compact(uint64_t(start) >> 1));
}

int64_t PlaneTileView::find(uint32_t x, uint32_t y) const {
  const uint64_t m = morton_encode(x, y);
  const uint32_t after = first_block_after(m, 0, plane_count);
  return after > 0 && m < block_end(after - 1) ? int64_t(after - 1) : -1;
}

uint32_t PlaneTileView::block_start(uint32_t i) const {
  return load_le<uint32_t>(records.data() + size_t(i) * kRecordSize + kOffStart);
}

uint32_t PlaneTileView::block_shift(uint32_t i) const { return records[size_t(i) * kRecordSize + kOffShift]; }

uint64_t PlaneTileView::block_end(uint32_t i) const {
  return uint64_t(block_start(i)) + (uint64_t(1) << (2 * block_shift(i)));
}

uint32_t PlaneTileView::first_block_after(uint64_t m, uint32_t lo, uint32_t hi) const {
  while (lo < hi) {
    const uint32_t mid = lo + (hi - lo) / 2;
    if (block_start(mid) <= m) lo = mid + 1;
    else hi = mid;
  }
  return lo;
}

PlaneTileView validate_plane_tile(std::span<const uint8_t> b) {
  if (b.size() < kHeaderSize)
    fail("header", 0, std::to_string(b.size()) + " bytes, need at least " + std::to_string(kHeaderSize));
  if (load_le<uint32_t>(b.data()) != kMagic) fail("magic", kOffMagic, "not \"STPN\"");
  const uint16_t version = load_le<uint16_t>(b.data() + kOffVersion);
  if (version != kVersion && version != kVersionNarrow)
    fail("version", kOffVersion,
         "version " + std::to_string(version) + ", this reader knows " + std::to_string(kVersionNarrow) + " and " +
             std::to_string(kVersion));
  const uint32_t levels = b[kOffLevels];
  if (levels < 1 || levels > kMaxLevels) fail("levels", kOffLevels, std::to_string(levels) + " outside 1..17");
  if (b[kOffFlags] != 0) fail("flags", kOffFlags, "unknown flags " + std::to_string(b[kOffFlags]));
  const uint32_t count = load_le<uint32_t>(b.data() + kOffPlaneCount);
  if (count < 1 || count > kMaxPlanes) fail("block_count", kOffPlaneCount, std::to_string(count) + " outside 1..2^20");
  const uint32_t byte_size = load_le<uint32_t>(b.data() + kOffByteSize);
  if (byte_size != b.size())
    fail("byte_size", kOffByteSize, std::to_string(byte_size) + " but the buffer holds " + std::to_string(b.size()));
  const uint32_t tables = load_le<uint32_t>(b.data() + kOffTableCount);
  if (tables < 1 || tables > kMaxTable) fail("table_count", kOffTableCount, std::to_string(tables) + " outside 1..65535");
  const uint32_t label_count = load_le<uint32_t>(b.data() + kOffLabelCount);
  if (label_count > kMaxTable || label_count > uint64_t(kWideSlots) * count)
    fail("label_count", kOffLabelCount, std::to_string(label_count) + " outside 0..min(65535, 2 block_count)");
  const size_t blocks_at = kHeaderSize + size_t(tables) * kEntrySize;
  const size_t labels_at = blocks_at + size_t(count) * kRecordSize;
  const size_t inner_at = labels_at + size_t(label_count) * kLabelSize;
  if (inner_at + 4 > b.size())
    fail("block_count", kOffPlaneCount,
         std::to_string(tables) + " planes, " + std::to_string(count) + " blocks and " + std::to_string(label_count) +
             " labelled blocks leave no inner buffer");
  PlaneTileView v;
  v.finest_level = levels - 1;
  v.plane_count = count;
  v.table_count = tables;
  v.table = b.subspan(kHeaderSize, blocks_at - kHeaderSize);
  v.label_count = label_count;
  v.records = b.subspan(blocks_at, labels_at - blocks_at);
  v.labels = b.subspan(labels_at, inner_at - labels_at);
  v.inner = b.subspan(inner_at);
  if (is_plane_buffer(v.inner)) fail("inner", inner_at, "a plane tile inside a plane tile");
  for (uint32_t i = 0; i < tables; ++i) {
    const size_t at = kHeaderSize + size_t(i) * kEntrySize;
    if (abs64(int64_t(load_le<uint64_t>(b.data() + at + kOffB))) > kMaxSlope)
      fail("plane " + std::to_string(i) + " b", at + kOffB, "|b| > 2^52");
    if (abs64(int64_t(load_le<uint64_t>(b.data() + at + kOffC))) > kMaxSlope)
      fail("plane " + std::to_string(i) + " c", at + kOffC, "|c| > 2^52");
  }
  const uint64_t texels = uint64_t(1) << (2 * v.finest_level);
  uint64_t end = 0;
  uint32_t labelled = 0;
  for (uint32_t i = 0; i < count; ++i) {
    const size_t at = blocks_at + size_t(i) * kRecordSize;
    const std::string what = "block " + std::to_string(i);
    const uint8_t kind = b[at + kOffKind];
    if (kind != kKindPlane && kind != kKindLabels && (kind != kKindWide || version != kVersion))
      fail(what + " kind", at + kOffKind,
           "unknown kind " + std::to_string(kind) + (kind == kKindWide ? " in a version 2 tile" : ""));
    const uint32_t index = load_le<uint16_t>(b.data() + at + kOffIndex);
    const uint32_t slots = kind == kKindWide ? kWideSlots : 1;
    const uint64_t limit = kind == kKindPlane ? tables : label_count;
    if (index + uint64_t(kind == kKindPlane ? 1 : slots) > limit)
      fail(what + " index", at + kOffIndex,
           std::to_string(index) + (kind == kKindPlane ? " >= " + std::to_string(limit) + " planes"
                                                       : " past the " + std::to_string(limit) + " label slots"));
    if (kind != kKindPlane) {
      if (b[at + kOffShift] != kLabelShift) fail(what + " shift", at + kOffShift, "a labelled block's shift is not 3");
      if (index != labelled) fail(what + " index", at + kOffIndex, "labelled blocks not in order");
      labelled += slots;
      const size_t lat = labels_at + size_t(index) * kLabelSize;
      const uint32_t entries = kind == kKindWide ? kWidePalette : kPalette;
      for (uint32_t k = 0; k < entries; ++k)
        if (load_le<uint16_t>(b.data() + lat + 2 * k) >= tables)
          fail("labelled block " + std::to_string(index) + " palette", lat + 2 * k, "plane index >= " + std::to_string(tables));
      if (kind == kKindWide)
        for (size_t k = kOffWidePad; k < kWideSize; ++k)
          if (b[lat + k] != 0) fail("labelled block " + std::to_string(index) + " padding", lat + k, "not zero");
    }
    const Plane p = v.plane(i);
    if (p.shift < kMinShift || p.shift > kMaxShift || p.shift > v.finest_level)
      fail(what + " shift", at + kOffShift, std::to_string(p.shift) + " outside 2..min(8, finest level)");
    const uint64_t size = uint64_t(1) << (2 * p.shift);
    if (p.start % size != 0) fail(what + " start", at + kOffStart, "not aligned to its block");
    if (p.start < end) fail(what + " start", at + kOffStart, "blocks unsorted or overlapping");
    if (p.start + size > texels) fail(what + " start", at + kOffStart, "outside the tile");
    end = p.start + size;
    // Each plane the block can answer with, at the block's corner (plane_format.hpp).
    const uint32_t x0 = morton_compact(p.start), y0 = morton_compact(uint64_t(p.start) >> 1);
    for (uint32_t k = 0; k < (kind == kKindPlane ? 1u : 64u); ++k)
      if (abs64(v.plane_at(i, x0 + k % 8, y0 + k / 8).a) > kMaxBase)
        fail(what + " plane", at + kOffIndex, "|a| at the block's corner > 2^61");
  }
  if (labelled != label_count)
    fail("label_count", kOffLabelCount,
         std::to_string(label_count) + " but the labelled blocks take " + std::to_string(labelled) + " slots");
  return v;
}

std::unique_ptr<Evaluator> open_plane_tile(
    std::span<const uint8_t> bytes,
    const std::function<std::unique_ptr<Evaluator>(std::span<const uint8_t>)>& open_inner) {
  const PlaneTileView v = validate_plane_tile(bytes);
  std::unique_ptr<Evaluator> inner = open_inner(v.inner);
  if (inner->finest_level() != v.finest_level)
    fail("inner", size_t(v.inner.data() - bytes.data()),
         "finest level " + std::to_string(inner->finest_level()) + ", the tile's is " + std::to_string(v.finest_level));
  return std::make_unique<PlaneTileEvaluator>(v, std::move(inner));
}

}  // namespace st
