// DAG-MH depth values (DAG-MH §3.3, §3.4, §3.6, Alg. 2): the values of the valued nodes
// in depth-first order, in chunks of 32. Per chunk a representative (base) value and a
// bitmap of the values that differ from it; those are `c_l + c_f * i` with k-bit
// multipliers i < 2^k (k <= 24), or raw float32 bits (k = 32).
//
// Decoder arithmetic (a format rule): the product is rounded to float, then the sum:
//     v = float(c_l + float(c_f * float(i)))      -- two roundings, NO fused multiply-add.
// The encoder (tiles/encode/dagmh_values_encode.hpp) verifies every value with exactly this function, so a decoder that fused
// the two operations could leave an admissible interval. affine_value() forbids the
// contraction itself (an empty asm barrier on the product) and every dagmh*.cpp is
// compiled with -ffp-contract=off as well (tiles/CMakeLists.txt). GPU ports must do the
// same (GLSL `precise`, CUDA __fmul_rn/__fadd_rn).
#pragma once
#include <bit>
#include <cstdint>
#include <span>
#include <vector>

#include "tiles/core/dagmh_format.hpp"

namespace st::dagmh {

inline float affine_value(float c_l, float c_f, uint32_t i) {
  float product = c_f * float(i);
#if defined(__GNUC__) && (defined(__x86_64__) || defined(__i386__))
  asm("" : "+x"(product));  // the product is materialised: nothing can fuse it with the add
#elif defined(__GNUC__)
  asm("" : "+g"(product));
#endif
  return c_l + product;
}

// Reads chunk `c` of a chunk section.
inline ChunkInfo load_chunk(const uint8_t* chunks, uint32_t c) {
  ChunkInfo info;
  std::memcpy(&info, chunks + size_t(c) * sizeof(ChunkInfo), sizeof(ChunkInfo));
  return info;
}

// Value `index` (Alg. 2). Preconditions, established by open_dagmh's validation: the
// chunk exists, its factor code is 0..24 or 31 (raw), and its multipliers end before the
// multiplier section's zero padding, so the 8-byte load stays in the buffer.
inline float read_value(const uint8_t* chunks, const uint8_t* multipliers, uint32_t index) {
  const uint8_t* c = chunks + size_t(index / kChunkValues) * sizeof(ChunkInfo);
  const uint32_t bit = index % kChunkValues;
  const uint32_t mask = st::load_le<uint32_t>(c + offsetof(ChunkInfo, mask));
  if (!((mask >> bit) & 1)) return std::bit_cast<float>(st::load_le<uint32_t>(c + offsetof(ChunkInfo, base)));
  const uint32_t packed = st::load_le<uint32_t>(c + offsetof(ChunkInfo, packed));
  const uint32_t code = packed >> kBitOffsetBits;
  const uint32_t k = code == kRawFactorCode ? kRawFactorBits : code;
  const uint32_t rank = bit_count(uint64_t(mask & ((1u << bit) - 1)));
  const uint64_t pos = uint64_t(packed & kBitOffsetMask) + uint64_t(rank) * k;
  const uint64_t word = st::load_le<uint64_t>(multipliers + (pos >> 3)) >> (pos & 7);
  const uint32_t i = uint32_t(word & ((uint64_t(1) << k) - 1));
  if (k == kRawFactorBits) return std::bit_cast<float>(i);
  return affine_value(std::bit_cast<float>(st::load_le<uint32_t>(c + offsetof(ChunkInfo, c_l))),
                      std::bit_cast<float>(st::load_le<uint32_t>(c + offsetof(ChunkInfo, c_f))), i);
}

// Where read_value(chunks, multipliers, index) reads its multiplier bits, or nullptr when
// the chunk's base answers (for a prefetch: it reads the chunk, so a caller that gathers
// many values prefetches the chunks first, then these, then reads the values).
inline const uint8_t* value_bits_at(const uint8_t* chunks, const uint8_t* multipliers, uint32_t index) {
  const uint8_t* c = chunks + size_t(index / kChunkValues) * sizeof(ChunkInfo);
  const uint32_t bit = index % kChunkValues;
  const uint32_t mask = st::load_le<uint32_t>(c + offsetof(ChunkInfo, mask));
  if (!((mask >> bit) & 1)) return nullptr;
  const uint32_t packed = st::load_le<uint32_t>(c + offsetof(ChunkInfo, packed));
  const uint32_t code = packed >> kBitOffsetBits;
  const uint32_t k = code == kRawFactorCode ? kRawFactorBits : code;
  const uint32_t rank = bit_count(uint64_t(mask & ((1u << bit) - 1)));
  const uint64_t pos = uint64_t(packed & kBitOffsetMask) + uint64_t(rank) * k;
  return multipliers + (pos >> 3);
}

}  // namespace st::dagmh
