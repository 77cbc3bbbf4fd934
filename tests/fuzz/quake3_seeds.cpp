#include "tests/fuzz/quake3_seeds.hpp"

#include <zlib.h>

#include <cstring>
#include <random>

namespace st::fuzz {
namespace {

template <class T>
void put(Bytes& out, T v) {
  uint8_t b[sizeof v];
  std::memcpy(b, &v, sizeof v);  // little-endian host, as the file format
  out.insert(out.end(), b, b + sizeof v);
}

struct Face {
  int32_t texture, type, vertex, nvert, meshvert, nmeshvert, patch_w = 0, patch_h = 0;
};

Bytes deflate_raw(const Bytes& in) {
  z_stream z{};
  deflateInit2(&z, 6, Z_DEFLATED, -MAX_WBITS, 8, Z_DEFAULT_STRATEGY);
  Bytes out(deflateBound(&z, uLong(in.size())));
  z.next_in = const_cast<Bytef*>(in.data());
  z.avail_in = uInt(in.size());
  z.next_out = out.data();
  z.avail_out = uInt(out.size());
  deflate(&z, Z_FINISH);
  out.resize(z.total_out);
  deflateEnd(&z);
  return out;
}

}  // namespace

std::vector<Bytes> quake3_maps(uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> coord(-256.0f, 256.0f);
  std::vector<Bytes> out;
  for (int variant = 0; variant < 12; ++variant) {
    Bytes lump[17];
    const char* names[] = {"textures/base/wall", "textures/base/curve", "textures/skies/blue", "textures/common/nodraw"};
    const int32_t flags[] = {0, 0, 0x4, 0x80};
    for (int t = 0; t < 4; ++t) {
      Bytes rec(64, 0);
      std::memcpy(rec.data(), names[t], std::strlen(names[t]));
      lump[1].insert(lump[1].end(), rec.begin(), rec.end());
      put(lump[1], flags[t]), put<int32_t>(lump[1], 1);
    }
    int32_t nvert = 0, nmv = 0;
    std::vector<Face> faces;
    auto vertex = [&](float x, float y, float z) {
      for (float c : {x, y, z}) put(lump[10], c);
      for (int k = 0; k < 4; ++k) put(lump[10], 0.0f);
      for (float c : {0.0f, 0.0f, 1.0f}) put(lump[10], c);
      put<uint32_t>(lump[10], 0xffffffffu);
      return nvert++;
    };
    const int nfaces = 1 + variant % 4;
    for (int f = 0; f < nfaces; ++f) {
      const int kind = (variant + f) % 4;
      const int32_t texture = int32_t(f % 5) - 1;  // -1 (untextured) .. 3
      if (kind == 0 || kind == 1) {  // polygon / mesh: a fan of n vertices
        const int n = 3 + int(rng() % 4);
        const int32_t first = nvert, first_mv = nmv;
        for (int k = 0; k < n; ++k) vertex(coord(rng), coord(rng), coord(rng));
        for (int k = 1; k + 1 < n; ++k) {
          for (int32_t m : {0, k, k + 1}) put(lump[11], m);
          nmv += 3;
        }
        faces.push_back({texture, kind == 0 ? 1 : 3, first, n, first_mv, nmv - first_mv});
      } else if (kind == 2) {  // patch
        const int w = 3 + 2 * int(rng() % 3), h = 3 + 2 * int(rng() % 2);
        const int32_t first = nvert;
        for (int j = 0; j < h; ++j)
          for (int i = 0; i < w; ++i) vertex(16.0f * float(i), 16.0f * float(j), coord(rng) * 0.1f);
        faces.push_back({texture < 0 ? 1 : texture, 2, first, w * h, 0, 0, w, h});
      } else {  // billboard
        faces.push_back({texture, 4, 0, std::min<int32_t>(1, nvert), 0, 0});
      }
    }
    if (variant % 3 == 0 && !faces.empty()) faces.push_back(faces.front());  // shared ranges
    for (const Face& f : faces) {
      for (int32_t v : {f.texture, -1, f.type, f.vertex, f.nvert, f.meshvert, f.nmeshvert, -1}) put(lump[13], v);
      lump[13].resize(lump[13].size() + 96 - 32, 0);
      put(lump[13], f.patch_w), put(lump[13], f.patch_h);
    }
    Bytes file = {'I', 'B', 'S', 'P'};
    put<int32_t>(file, 46);
    int32_t at = 8 + 17 * 8;
    for (const Bytes& l : lump) {
      put(file, l.empty() ? 0 : at), put(file, int32_t(l.size()));
      at += int32_t(l.size());
    }
    for (const Bytes& l : lump) file.insert(file.end(), l.begin(), l.end());
    out.push_back(std::move(file));
  }
  return out;
}

Bytes zip_archive(const std::vector<std::pair<std::string, Bytes>>& files, bool deflated) {
  Bytes out, central;
  for (const auto& [name, data] : files) {
    const uint32_t offset = uint32_t(out.size());
    const uint32_t crc = uint32_t(crc32(0, data.data(), uInt(data.size())));
    const Bytes body = deflated ? deflate_raw(data) : data;
    const uint16_t method = deflated ? 8 : 0, name_len = uint16_t(name.size());
    const uint32_t packed = uint32_t(body.size()), size = uint32_t(data.size());
    put<uint32_t>(out, 0x04034b50u);
    for (uint16_t v : {uint16_t(20), uint16_t(0), method, uint16_t(0), uint16_t(0)}) put(out, v);
    put(out, crc), put(out, packed), put(out, size), put(out, name_len), put<uint16_t>(out, 0);
    out.insert(out.end(), name.begin(), name.end());
    out.insert(out.end(), body.begin(), body.end());
    put<uint32_t>(central, 0x02014b50u);
    for (uint16_t v : {uint16_t(20), uint16_t(20), uint16_t(0), method, uint16_t(0), uint16_t(0)}) put(central, v);
    put(central, crc), put(central, packed), put(central, size), put(central, name_len);
    for (uint16_t v : {0, 0, 0, 0}) put(central, v);
    put<uint32_t>(central, 0), put(central, offset);
    central.insert(central.end(), name.begin(), name.end());
  }
  const uint32_t cd_at = uint32_t(out.size()), cd_size = uint32_t(central.size());
  out.insert(out.end(), central.begin(), central.end());
  put<uint32_t>(out, 0x06054b50u);
  const uint16_t n = uint16_t(files.size());
  for (uint16_t v : {uint16_t(0), uint16_t(0), n, n}) put(out, v);
  put(out, cd_size), put(out, cd_at), put<uint16_t>(out, 0);
  return out;
}

}  // namespace st::fuzz
