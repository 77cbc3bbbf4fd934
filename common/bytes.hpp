// Little-endian field access for every format of the project (packs, tiles, frames).
// One copy for all modules: loads and stores go through memcpy, so floats round-trip
// bit-exactly and unaligned fields are fine. The host must be little-endian, as every
// target of this project is (checked at compile time).
//
// These helpers do not check bounds: the caller has checked `offset + sizeof(T)` against
// its buffer (proto's bounded Reader, the tile validators, the pack parsers do so before
// every read).
#pragma once
#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>
#include <type_traits>
#include <vector>

namespace st {

static_assert(std::endian::native == std::endian::little,
              "shadowtile's formats are little-endian and read in place: a big-endian host is not supported");

template <class T>
inline T load_le(const uint8_t* p) {
  static_assert(std::is_trivially_copyable_v<T>);
  T v;
  std::memcpy(&v, p, sizeof(T));
  return v;
}

// Caller guarantees offset + sizeof(T) <= bytes.size().
template <class T>
inline T load_le(std::span<const uint8_t> bytes, size_t offset) {
  return load_le<T>(bytes.data() + offset);
}

template <class T>
inline void store_le(uint8_t* p, T v) {
  static_assert(std::is_trivially_copyable_v<T>);
  std::memcpy(p, &v, sizeof(T));
}

template <class T>
inline void append_le(std::vector<uint8_t>& out, T v) {
  const size_t at = out.size();
  out.resize(at + sizeof(T));
  store_le<T>(out.data() + at, v);
}

}  // namespace st
