// DAG-MH value chunks: our reconstruction of the encoder of DAG-MH §3.3 (partly missing
// from our copy of the paper), following ARCHITECTURE.md "Encodings":
//   1. base value: the point covered by the most admissible intervals of the chunk,
//      found by a sweep over the sorted bounds (the best point is always some lo);
//   2. the intervals not containing the base get multipliers: the fewest factor bits k
//      and a step c_f such that each contains c_l + c_f * i for an integer i < 2^k;
//   3. otherwise raw float32 bits (k = 32).
// Where an interval leaves a choice (the base, a k = 0 chunk's c_l, a raw value, the step
// among those that verify) the encoder takes the value whose bytes deflate best: the
// previous chunk's base or the roundest float (most trailing zero bits), a power-of-two
// step first. Any point of the intervals is lossless; the format is unchanged.
// Every value is checked with the decoder's exact float arithmetic (affine_value, no
// fma), and the packed chunks are decoded once more at the end: a value outside its
// interval is a bug and stops the encoder (ST_CHECK), never a silently lossy map.
#include "tiles/encode/dagmh_values_encode.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <string>

#include "common/error.hpp"

namespace st::dagmh {
namespace {

struct Span {
  float lo, hi;
  bool contains(float v) const { return lo <= v && v <= hi; }
};

// The float in [a, b] (a <= b, no NaN) with the most trailing zero bits: 0 if the
// interval holds it, else the common high bits of the ends' bit patterns (monotone in
// the value for each sign) with every lower bit clear. Any point of an admissible
// interval is lossless (MH 2016 §3.1), and round values deflate better.
float roundest_in(float a, float b) {
  if (a <= 0.0f && 0.0f <= b) return 0.0f;
  if (b < 0.0f) return -roundest_in(-b, -a);
  const uint32_t lo = std::bit_cast<uint32_t>(a), hi = std::bit_cast<uint32_t>(b);
  if (lo == hi) return a;
  const int m = 31 - std::countl_zero(lo ^ hi);  // highest differing bit: set in hi
  return std::bit_cast<float>((hi >> m) << m);
}

// Step 1: the sweep. #intervals containing t = #(lo <= t) - #(hi < t). The best count is
// reached at some lo, los[i], and holds on all of [los[i], the smallest hi >= los[i]]
// (every interval holding los[i] holds that whole range): the base is `prev` (the
// previous chunk's base, so the bytes repeat) if it lies there, else the roundest float
// there.
float sweep_base(std::span<const ValueSlot> slots, float prev) {
  float los[kChunkValues], his[kChunkValues];
  const size_t n = slots.size();
  for (size_t j = 0; j < n; ++j) los[j] = slots[j].lo, his[j] = slots[j].hi;
  std::sort(los, los + n);
  std::sort(his, his + n);
  float best = los[0], best_end = los[0];
  size_t best_count = 0, below = 0;
  for (size_t i = 0; i < n; ++i) {
    if (i + 1 < n && !(los[i] < los[i + 1])) continue;  // last of a run of equal lo
    while (below < n && his[below] < los[i]) ++below;
    const size_t count = i + 1 - below;
    if (count > best_count) best_count = count, best = los[i], best_end = his[below];
  }
  if (best <= prev && prev <= best_end) return prev;
  return roundest_in(best, best_end);
}

// Multiplier for `s` in progression (c_l, c_f) with i <= top, if some i lands in s.
bool find_multiplier(const Span& s, float c_l, float c_f, uint32_t top, uint32_t& out) {
  double t = (double(s.lo) - double(c_l)) / double(c_f);
  uint32_t i0 = 0;
  if (t > 0) i0 = t >= double(top) ? top : uint32_t(std::ceil(t));
  for (uint32_t cand : {i0, i0 - 1, i0 + 1}) {  // rounding may move the hit by one step
    if (cand > top) continue;                    // (i0 - 1 wraps to a huge value)
    if (s.contains(affine_value(c_l, c_f, cand))) return out = cand, true;
  }
  return false;
}

bool try_progression(std::span<const Span> rest, float c_l, float c_f, uint32_t k,
                     std::vector<uint32_t>& mult) {
  if (!std::isfinite(c_f) || !(c_f >= 0)) return false;
  const uint32_t top = uint32_t((uint64_t(1) << k) - 1);
  mult.clear();
  for (const Span& s : rest) {
    uint32_t i;
    if (!find_multiplier(s, c_l, c_f, top, i)) return false;
    mult.push_back(i);
  }
  return true;
}

struct Factors {
  float c_l = 0, c_f = 0;
  uint32_t k = kRawFactorBits;
  std::vector<uint32_t> mult;
};

// Step 2: fewest k. c_l is the smallest upper bound, so every interval lies (partly) at
// or above it; a step s with s * (2^k - 1) >= max lo - c_l reaches all of them, and an
// interval at least s wide always holds a point of the progression. Candidates per k:
// the smallest reaching step (and one a hair larger, against rounding at the top), and
// the power of two above it, which lands exactly on float grid points, so even
// zero-width intervals (open geometry, lo == hi) are hit when k covers their spacing.
Factors fit_factors(std::span<const Span> rest) {
  Factors f;
  float max_lo = -std::numeric_limits<float>::infinity();
  float min_hi = std::numeric_limits<float>::infinity();
  for (const Span& s : rest) max_lo = std::max(max_lo, s.lo), min_hi = std::min(min_hi, s.hi);
  if (max_lo <= min_hi) {  // all remaining intervals share [max_lo, min_hi]: k = 0
    const float c_l = roundest_in(max_lo, min_hi);
    for (float c : {c_l, max_lo})
      if (try_progression(rest, c, 0.0f, 0, f.mult)) {
        f.c_l = c, f.k = 0;
        return f;
      }
  }
  const float c_l = min_hi;
  const double span = double(max_lo) - double(c_l);
  if (!(span > 0) || !std::isfinite(span)) return f;
  auto fits = [&](uint32_t k, Factors& out) {
    const double s0 = span / double((uint64_t(1) << k) - 1);
    if (s0 > double(std::numeric_limits<float>::max())) return false;
    float up = float(s0);
    if (double(up) < s0) up = std::nextafter(up, std::numeric_limits<float>::infinity());
    int e = 0;
    const double m = std::frexp(s0, &e);  // s0 = m * 2^e, m in [0.5, 1)
    const float pow2 = m == 0.5 ? float(s0) : float(std::ldexp(1.0, e));
    for (float c_f : {pow2, up, up * (1.0f + 0x1p-20f)}) {  // the round step first: it deflates better
      if (try_progression(rest, c_l, c_f, k, out.mult)) {
        out.c_l = c_l, out.c_f = c_f, out.k = k;
        return true;
      }
    }
    return false;
  };
  // Feasibility grows with k (finer steps; power-of-two grids nest), so a binary search
  // finds the fewest bits; where rounding breaks monotonicity it may return a few bits
  // more than necessary, never an unverified k.
  Factors best;
  if (!fits(kMaxFactorBits, best)) return f;
  uint32_t lo = 1, hi = kMaxFactorBits;  // hi: verified feasible
  while (lo < hi) {
    const uint32_t mid = (lo + hi) / 2;
    Factors trial;
    if (fits(mid, trial)) hi = mid, best = std::move(trial);
    else lo = mid + 1;
  }
  return best;
}

class BitWriter {
 public:
  uint64_t bits() const { return bits_; }
  void put(uint32_t v, uint32_t k) {  // k <= 32 bits, least significant first
    if (k == 0) return;
    const uint64_t value = uint64_t(v) & ((uint64_t(1) << k) - 1);
    const uint64_t word = bits_ >> 6, shift = bits_ & 63;
    if (word + 2 > words_.size()) words_.resize(word + 2, 0);
    words_[word] |= value << shift;
    if (shift + k > 64) words_[word + 1] |= value >> (64 - shift);
    bits_ += k;
  }
  std::vector<uint8_t> finish() const {
    std::vector<uint8_t> bytes(align4((bits_ + 7) / 8) + kMultiplierPadBytes, 0);
    for (size_t b = 0; b < (bits_ + 7) / 8; ++b) bytes[b] = uint8_t(words_[b >> 3] >> (8 * (b & 7)));
    return bytes;
  }

 private:
  std::vector<uint64_t> words_;
  uint64_t bits_ = 0;
};

}  // namespace

EncodedValues encode_values(std::span<const ValueSlot> slots) {
  for (size_t j = 0; j < slots.size(); ++j)
    if (!(slots[j].lo <= slots[j].hi))
      throw Error("dagmh: value " + std::to_string(j) + " has an invalid interval [" +
                  std::to_string(slots[j].lo) + ", " + std::to_string(slots[j].hi) + "]");
  EncodedValues out;
  BitWriter writer;
  std::vector<Span> rest;
  for (size_t first = 0; first < slots.size(); first += kChunkValues) {
    auto chunk = slots.subspan(first, std::min<size_t>(kChunkValues, slots.size() - first));
    ChunkInfo info{};
    info.base = sweep_base(chunk, out.chunks.empty() ? 0.0f : out.chunks.back().base);
    rest.clear();
    for (size_t j = 0; j < chunk.size(); ++j) {
      if (Span{chunk[j].lo, chunk[j].hi}.contains(info.base)) continue;
      info.mask |= 1u << j;
      rest.push_back({chunk[j].lo, chunk[j].hi});
    }
    Factors f;
    if (!rest.empty()) f = fit_factors(rest);
    if (rest.empty()) f.k = 0;
    if (f.k == kRawFactorBits) {
      f.mult.clear();
      for (size_t j = 0; j < chunk.size(); ++j) {
        if (!((info.mask >> j) & 1)) continue;
        const ValueSlot& s = chunk[j];
        f.mult.push_back(std::bit_cast<uint32_t>(roundest_in(s.lo, s.hi)));
      }
    }
    // The chunk info holds the first multiplier's bit offset in 27 bits (16 MiB of
    // multipliers; a tile cut deeper holds fewer).
    if (writer.bits() > kBitOffsetMask) throw Error("dagmh: multiplier section exceeds 2^27 bits");
    info.c_l = f.c_l, info.c_f = f.c_f;
    info.packed = pack_factor(uint32_t(writer.bits()), f.k);
    for (uint32_t m : f.mult) writer.put(m, f.k);
    out.chunks.push_back(info);
    ++out.stats.chunks;
    out.stats.base_only_chunks += info.mask == 0;
    out.stats.raw_chunks += f.k == kRawFactorBits && info.mask != 0;
    out.stats.multipliers += f.mult.size();
    out.stats.multiplier_bits += uint64_t(f.mult.size()) * f.k;
  }
  out.multipliers = writer.finish();
  // Decode everything with the reader the evaluator uses: the lossless invariant is
  // checked here on the exact bytes, not on the encoder's intentions.
  const auto* chunk_bytes = reinterpret_cast<const uint8_t*>(out.chunks.data());
  for (size_t j = 0; j < slots.size(); ++j) {
    const float v = read_value(chunk_bytes, out.multipliers.data(), uint32_t(j));
    ST_CHECK(slots[j].lo <= v && v <= slots[j].hi);
  }
  return out;
}

}  // namespace st::dagmh
