// Stored-tile codecs measured against the pack's zlib (level 6) by bench_stack_slices
// (tiles/core/MHOCT.md "Stored-tile codecs against zlib"): what a tile's stored bytes would
// be with another entropy stage, decoded back to the same raw bytes (checked on every tile
// the bench measures), and how fast they decode. Measurement only: no pack stores them.
//
//   lzma: a raw LZMA1 stream (liblzma, Debian 12 liblzma-dev) of the tile's stored-form raw
//     bytes, literal context lc = 0, literal position bits lp = 2 and pb = 2 (so each byte of
//     a 4-byte word has its own literal model: value words' sign/exponent bytes apart from
//     their low mantissa bytes), preset 6, the dictionary the raw size rounded up to a power
//     of two (at least 4 KiB): the decoder's memory is that dictionary plus a fixed state of tens of KB of
//     probabilities, bounded by the tile bound. Both sides fix the properties, so the stream
//     carries no header; its raw size is the index entry's, as for zlib.
//   zstd: libzstd (already a benchmark dependency) at level 19, one frame per tile.
//   Adaptive order-0 estimates (Krichevsky-Trofimov, a model per byte position of a 4-byte
//   word, reset per tile as a per-tile codec would be): the bits an ideal entropy coder
//   spends on a word sequence, raw or as residuals (xor) against a prediction; no coder.
#pragma once
#include <zstd.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#if ST_BENCH_LZMA
#include <lzma.h>
#endif

namespace st::bench {

#if ST_BENCH_LZMA
inline uint32_t lzma_dict_size(size_t raw) {
  uint32_t d = 4096;
  while (d < raw && d < (1u << 30)) d <<= 1;
  return d;
}

inline lzma_options_lzma lzma_tile_options(size_t raw) {
  lzma_options_lzma o{};
  if (lzma_lzma_preset(&o, 6)) throw std::runtime_error("lzma: preset 6 refused");
  o.lc = 0, o.lp = 2, o.pb = 2, o.dict_size = lzma_dict_size(raw);
  return o;
}

inline std::vector<uint8_t> lzma_tile_compress(std::span<const uint8_t> raw) {
  lzma_options_lzma o = lzma_tile_options(raw.size());
  const lzma_filter f[2] = {{LZMA_FILTER_LZMA1, &o}, {LZMA_VLI_UNKNOWN, nullptr}};
  lzma_stream s = LZMA_STREAM_INIT;
  if (lzma_raw_encoder(&s, f) != LZMA_OK) throw std::runtime_error("lzma: encoder refused its options");
  std::vector<uint8_t> out(raw.size() + raw.size() / 2 + 1024);
  s.next_in = raw.data(), s.avail_in = raw.size(), s.next_out = out.data(), s.avail_out = out.size();
  lzma_ret r;
  do r = lzma_code(&s, LZMA_FINISH);
  while (r == LZMA_OK && s.avail_out > 0);
  const size_t n = out.size() - s.avail_out;
  lzma_end(&s);
  if (r != LZMA_STREAM_END) throw std::runtime_error("lzma: encode failed (" + std::to_string(int(r)) + ")");
  out.resize(n);
  return out;
}

// Decodes exactly out.size() bytes (the recorded raw size) from `stored`; throws when the
// stream is malformed, ends early or has bytes left (a hostile stream cannot write past
// `out` nor make the decoder hold more than the dictionary).
inline void lzma_tile_decompress_into(std::span<const uint8_t> stored, std::span<uint8_t> out) {
  lzma_options_lzma o{};
  o.lc = 0, o.lp = 2, o.pb = 2, o.dict_size = lzma_dict_size(out.size());
  const lzma_filter f[2] = {{LZMA_FILTER_LZMA1, &o}, {LZMA_VLI_UNKNOWN, nullptr}};
  lzma_stream s = LZMA_STREAM_INIT;
  if (lzma_raw_decoder(&s, f) != LZMA_OK) throw std::runtime_error("lzma: decoder refused its options");
  s.next_in = stored.data(), s.avail_in = stored.size(), s.next_out = out.data(), s.avail_out = out.size();
  const lzma_ret r = lzma_code(&s, LZMA_RUN);
  const bool ok = (r == LZMA_OK || r == LZMA_STREAM_END) && s.avail_out == 0;
  lzma_end(&s);
  if (!ok) throw std::runtime_error("lzma: stream does not decode to the recorded size");
}
#endif

inline std::vector<uint8_t> zstd_tile_compress(std::span<const uint8_t> raw, int level = 19) {
  std::vector<uint8_t> out(ZSTD_compressBound(raw.size()));
  const size_t n = ZSTD_compress(out.data(), out.size(), raw.data(), raw.size(), level);
  if (ZSTD_isError(n)) throw std::runtime_error(std::string("zstd: ") + ZSTD_getErrorName(n));
  out.resize(n);
  return out;
}

inline void zstd_tile_decompress_into(std::span<const uint8_t> stored, std::span<uint8_t> out) {
  const size_t n = ZSTD_decompress(out.data(), out.size(), stored.data(), stored.size());
  if (ZSTD_isError(n) || n != out.size()) throw std::runtime_error("zstd: frame does not decode to the recorded size");
}

// Adaptive order-0 cost of a word sequence, one model per byte position (KT estimator).
struct WordCost {
  double count[4][256];
  double total[4];
  double bits = 0;
  WordCost() { reset(); }
  void reset() {
    for (auto& row : count)
      for (double& c : row) c = 0.5;
    for (double& t : total) t = 128;
  }
  void code(uint32_t v) {
    for (int p = 0; p < 4; ++p) {
      const uint8_t s = uint8_t(v >> (8 * p));
      bits -= std::log2(count[p][s] / total[p]);
      count[p][s] += 1, total[p] += 1;
    }
  }
};

}  // namespace st::bench
