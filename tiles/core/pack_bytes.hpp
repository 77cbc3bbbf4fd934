// Little-endian field access for the pack formats (tile_cut_grid, pack_format): every
// read is bounds-checked by the caller's span; the host must be little-endian (as every
// target of this project is), which lets floats round-trip bit-exactly through memcpy.
#pragma once
#include <bit>
#include <cstdint>
#include <cstring>
#include <span>
#include <vector>

namespace st::packbytes {

static_assert(std::endian::native == std::endian::little, "pack formats assume a little-endian host");

template <class T>
inline void put(std::vector<uint8_t>& out, T v) {
  size_t at = out.size();
  out.resize(at + sizeof(T));
  std::memcpy(out.data() + at, &v, sizeof(T));
}
template <class T>
inline void store(uint8_t* at, T v) {
  std::memcpy(at, &v, sizeof(T));
}
// Caller guarantees offset + sizeof(T) <= bytes.size().
template <class T>
inline T load(std::span<const uint8_t> bytes, size_t offset) {
  T v;
  std::memcpy(&v, bytes.data() + offset, sizeof(T));
  return v;
}

}  // namespace st::packbytes
