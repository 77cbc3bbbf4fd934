#include "tiles/bake/scene_q3bsp.hpp"

#include <zlib.h>

#include <algorithm>
#include <cctype>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <vector>

#include "tiles/core/error.hpp"

namespace st {
namespace {

// Quake 3 BSP version 46 layout (little-endian), as assimp's parser reads it:
//   0   char[4] "IBSP"      4   int32 version (46)
//   8   17 lumps x {int32 offset, int32 size}  -> header of 144 bytes
// Record sizes of the lumps assimp uses: texture 72, vertex 44, mesh vertex 4,
// face 104, lightmap 128*128*3.
constexpr size_t kHeaderSize = 8 + 17 * 8;
enum Lump { kEntities = 0, kTextures = 1, kVertices = 10, kMeshVerts = 11, kFaces = 13, kLightmaps = 14 };
constexpr size_t kTextureSize = 72, kVertexSize = 44, kMeshVertSize = 4, kFaceSize = 104,
                 kLightmapSize = 128 * 128 * 3;

int32_t read_i32(const std::vector<uint8_t>& data, size_t at) {
  int32_t v;
  std::memcpy(&v, data.data() + at, sizeof v);  // bounds checked by the callers
  return v;
}

void check_bsp(const std::vector<uint8_t>& data, const std::string& where) {
  auto fail = [&](const std::string& what) { throw Error(where + ": malformed Quake 3 map: " + what); };
  if (data.size() < kHeaderSize) fail("file of " + std::to_string(data.size()) + " bytes is shorter than the 144-byte header");
  if (std::memcmp(data.data(), "IBSP", 4) != 0) fail("magic is not IBSP");
  if (read_i32(data, 4) != 46) fail("version " + std::to_string(read_i32(data, 4)) + " is not 46");
  size_t offset[17], count[17];
  const size_t record[17] = {1, kTextureSize, 1, 1, 1, 1, 1, 1, 1, 1, kVertexSize, kMeshVertSize, 1, kFaceSize, kLightmapSize, 1, 1};
  for (int l = 0; l < 17; ++l) {
    const int32_t off = read_i32(data, 8 + 8 * l), size = read_i32(data, 12 + 8 * l);
    if (off < 0 || size < 0 || size_t(off) + size_t(size) > data.size())
      fail("lump " + std::to_string(l) + " (offset " + std::to_string(off) + ", size " + std::to_string(size) +
           ") lies outside the file of " + std::to_string(data.size()) + " bytes");
    if (size_t(size) % record[l] != 0)
      fail("lump " + std::to_string(l) + " size " + std::to_string(size) + " is not a multiple of its record size " +
           std::to_string(record[l]));
    offset[l] = size_t(off);
    count[l] = size_t(size) / record[l];
  }
  for (size_t f = 0; f < count[kFaces]; ++f) {
    const size_t at = offset[kFaces] + f * kFaceSize;
    const int32_t texture = read_i32(data, at), vertex = read_i32(data, at + 12), nvert = read_i32(data, at + 16);
    const int32_t meshvert = read_i32(data, at + 20), nmeshvert = read_i32(data, at + 24),
                  lightmap = read_i32(data, at + 28);
    const std::string face = "face " + std::to_string(f) + ": ";
    if (texture < -1 || (texture >= 0 && size_t(texture) >= count[kTextures])) fail(face + "texture index out of range");
    if (lightmap < -1 || (lightmap >= 0 && size_t(lightmap) >= count[kLightmaps]))
      fail(face + "lightmap index out of range");
    if (vertex < 0 || nvert < 0 || size_t(vertex) + size_t(nvert) > count[kVertices])
      fail(face + "vertex range out of range");
    if (meshvert < 0 || nmeshvert < 0 || size_t(meshvert) + size_t(nmeshvert) > count[kMeshVerts])
      fail(face + "mesh-vertex range out of range");
    for (int32_t k = 0; k < nmeshvert; ++k) {
      const int32_t index = read_i32(data, offset[kMeshVerts] + (size_t(meshvert) + k) * kMeshVertSize);
      if (index < 0 || index >= nvert) fail(face + "mesh vertex " + std::to_string(index) + " outside the face's vertices");
    }
  }
}

uint32_t read_u32(const std::vector<uint8_t>& d, size_t at) {
  return uint32_t(d[at]) | uint32_t(d[at + 1]) << 8 | uint32_t(d[at + 2]) << 16 | uint32_t(d[at + 3]) << 24;
}
uint16_t read_u16(const std::vector<uint8_t>& d, size_t at) { return uint16_t(d[at] | d[at + 1] << 8); }

// The .bsp members of a zip archive (PKWARE APPNOTE 4.3: end of central directory record
// 22 bytes + comment, central directory entries 46 bytes + name + extra + comment, local
// headers 30 bytes + name + extra), stored or deflated. Every offset and length is
// checked against the archive before use. A file without an end record is not a zip:
// no entries (assimp then fails to open it and says so).
std::vector<std::pair<std::string, std::vector<uint8_t>>> bsp_entries(const std::vector<uint8_t>& zip,
                                                                      const std::string& path) {
  constexpr size_t kEndSize = 22, kCentralSize = 46, kLocalSize = 30;
  constexpr size_t kMaxMember = size_t(1) << 30;  // no real map is near 1 GiB
  auto fail = [&](const std::string& what) { throw Error(path + ": malformed zip archive: " + what); };
  std::vector<std::pair<std::string, std::vector<uint8_t>>> out;
  if (zip.size() < kEndSize) return out;
  size_t end = std::string::npos;
  for (size_t at = zip.size() - kEndSize + 1; at-- > 0 && zip.size() - at <= kEndSize + 65535;)
    if (read_u32(zip, at) == 0x06054b50u) {
      end = at;
      break;
    }
  if (end == std::string::npos) return out;
  const size_t entries = read_u16(zip, end + 10), cd_size = read_u32(zip, end + 12), cd_at = read_u32(zip, end + 16);
  if (cd_at > end || cd_size > end - cd_at) fail("central directory outside the file");
  size_t at = cd_at;
  for (size_t e = 0; e < entries; ++e) {
    if (at + kCentralSize > cd_at + cd_size || read_u32(zip, at) != 0x02014b50u) fail("bad central directory entry " + std::to_string(e));
    const uint16_t method = read_u16(zip, at + 10);
    const size_t packed = read_u32(zip, at + 20), size = read_u32(zip, at + 24);
    const size_t name_len = read_u16(zip, at + 28), extra = read_u16(zip, at + 30), comment = read_u16(zip, at + 32);
    const size_t local = read_u32(zip, at + 42);
    if (at + kCentralSize + name_len > cd_at + cd_size) fail("entry name outside the central directory");
    std::string name(zip.begin() + long(at + kCentralSize), zip.begin() + long(at + kCentralSize + name_len));
    at += kCentralSize + name_len + extra + comment;
    std::string lower = name;
    for (char& c : lower) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    if (lower.size() < 4 || lower.compare(lower.size() - 4, 4, ".bsp") != 0) continue;
    if (local + kLocalSize > zip.size() || read_u32(zip, local) != 0x04034b50u) fail("bad local header of '" + name + "'");
    const size_t data_at = local + kLocalSize + read_u16(zip, local + 26) + read_u16(zip, local + 28);
    if (data_at > zip.size() || packed > zip.size() - data_at) fail("data of '" + name + "' outside the file");
    if (size > kMaxMember) fail("'" + name + "' claims " + std::to_string(size) + " bytes");
    std::vector<uint8_t> data(size);
    if (method == 0) {
      if (packed != size) fail("stored '" + name + "' has different packed and unpacked sizes");
      std::copy_n(zip.begin() + long(data_at), size, data.begin());
    } else if (method == 8) {
      z_stream z{};
      if (inflateInit2(&z, -MAX_WBITS) != Z_OK) fail("zlib init");
      z.next_in = const_cast<Bytef*>(zip.data() + data_at);
      z.avail_in = static_cast<uInt>(packed);
      z.next_out = data.data();
      z.avail_out = static_cast<uInt>(size);
      const int rc = inflate(&z, Z_FINISH);
      const size_t produced = z.total_out;
      inflateEnd(&z);
      if (rc != Z_STREAM_END || produced != size) fail("'" + name + "' does not inflate to its stated size");
    } else {
      fail("'" + name + "' uses unsupported compression method " + std::to_string(method));
    }
    out.push_back({name, std::move(data)});
  }
  return out;
}

}  // namespace

void check_quake3_archive(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return;  // assimp reports unreadable files itself
  const std::vector<uint8_t> zip((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  for (const auto& [name, data] : bsp_entries(zip, path)) check_bsp(data, path + ": " + name);
}

}  // namespace st
