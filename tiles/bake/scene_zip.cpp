#include "tiles/bake/scene_zip.hpp"

#include <zlib.h>

#include <algorithm>
#include <cctype>
#include <cstring>

#include "common/error.hpp"

namespace st {
namespace {

// PKWARE APPNOTE 6.3 layouts (little-endian):
//   end of central directory: 22 bytes + comment; entries at +10 (u16), directory size at
//     +12 (u32), directory offset at +16 (u32)
//   central directory entry: 46 bytes + name + extra + comment; method +10 (u16), packed
//     size +20, size +24 (u32), name/extra/comment lengths +28/+30/+32 (u16), local header
//     offset +42 (u32), CRC-32 of the uncompressed data +16 (u32)
//   local header: 30 bytes + name + extra; name/extra lengths +26/+28 (u16)
constexpr size_t kEndSize = 22, kCentralSize = 46, kLocalSize = 30, kMaxComment = 65535;
constexpr uint32_t kEndMagic = 0x06054b50u, kCentralMagic = 0x02014b50u, kLocalMagic = 0x04034b50u;
constexpr size_t kMaxMember = size_t(1) << 30, kMaxDeflateRatio = 1032;

uint32_t u32(const std::vector<uint8_t>& d, size_t at) {
  return uint32_t(d[at]) | uint32_t(d[at + 1]) << 8 | uint32_t(d[at + 2]) << 16 | uint32_t(d[at + 3]) << 24;
}
uint16_t u16(const std::vector<uint8_t>& d, size_t at) { return uint16_t(d[at] | d[at + 1] << 8); }

bool ends_with_lower(std::string name, const std::string& suffix) {
  for (char& c : name) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return name.size() >= suffix.size() && name.compare(name.size() - suffix.size(), suffix.size(), suffix) == 0;
}

}  // namespace

std::optional<std::vector<ZipEntry>> list_zip(const std::vector<uint8_t>& zip, const std::string& path,
                                              const std::string& suffix) {
  auto fail = [&](const std::string& what) { throw Error(path + ": malformed zip archive: " + what); };
  if (zip.size() < kEndSize) return std::nullopt;
  size_t end = std::string::npos;
  for (size_t at = zip.size() - kEndSize + 1; at-- > 0 && zip.size() - at <= kEndSize + kMaxComment;)
    if (u32(zip, at) == kEndMagic) {
      end = at;
      break;
    }
  if (end == std::string::npos) return std::nullopt;
  const size_t entries = u16(zip, end + 10), cd_size = u32(zip, end + 12), cd_at = u32(zip, end + 16);
  if (cd_at > end || cd_size > end - cd_at) fail("central directory outside the file");
  const size_t cd_end = cd_at + cd_size;
  std::vector<ZipEntry> out;
  size_t at = cd_at;
  for (size_t e = 0; e < entries; ++e) {
    if (at > cd_end || cd_end - at < kCentralSize || u32(zip, at) != kCentralMagic)
      fail("bad central directory entry " + std::to_string(e));
    ZipEntry entry;
    entry.method = u16(zip, at + 10);
    entry.crc = u32(zip, at + 16);
    entry.packed = u32(zip, at + 20);
    entry.size = u32(zip, at + 24);
    const size_t name_len = u16(zip, at + 28), extra = u16(zip, at + 30), comment = u16(zip, at + 32);
    const size_t local = u32(zip, at + 42);
    if (cd_end - at - kCentralSize < name_len) fail("entry " + std::to_string(e) + " name outside the directory");
    entry.name.assign(zip.begin() + long(at + kCentralSize), zip.begin() + long(at + kCentralSize + name_len));
    at += kCentralSize + name_len + extra + comment;
    if (!ends_with_lower(entry.name, suffix)) continue;
    if (local > zip.size() || zip.size() - local < kLocalSize || u32(zip, local) != kLocalMagic)
      fail("bad local header of '" + entry.name + "'");
    entry.data_at = local + kLocalSize + u16(zip, local + 26) + u16(zip, local + 28);
    if (entry.data_at > zip.size() || entry.packed > zip.size() - entry.data_at)
      fail("data of '" + entry.name + "' outside the file");
    if (entry.size > kMaxMember) fail("'" + entry.name + "' claims " + std::to_string(entry.size) + " bytes");
    // What extract_zip will allocate is checked here, against the bytes really present:
    // a stored member is its packed bytes; deflate expands at most 1032:1 (RFC 1951: a
    // 258-byte match per 2 bits at best); nothing else is read.
    if (entry.method == 0 && entry.packed != entry.size)
      fail("'" + entry.name + "' is stored with different packed and unpacked sizes");
    if (entry.method == 8 && entry.size > kMaxDeflateRatio * entry.packed + 64)
      fail("'" + entry.name + "' claims " + std::to_string(entry.size) + " bytes from " +
           std::to_string(entry.packed) + " deflated bytes, more than deflate can expand to");
    if (entry.method != 0 && entry.method != 8)
      fail("'" + entry.name + "' uses unsupported compression method " + std::to_string(entry.method));
    out.push_back(std::move(entry));
  }
  return out;
}

std::vector<uint8_t> extract_zip(const std::vector<uint8_t>& zip, const std::string& path, const ZipEntry& entry,
                                 std::string_view magic) {
  auto fail = [&](const std::string& what) {
    throw Error(path + ": malformed zip archive: '" + entry.name + "' " + what);
  };
  ST_CHECK(entry.data_at <= zip.size() && entry.packed <= zip.size() - entry.data_at);
  // Checked before allocating (list_zip checks the same for the entries it returns).
  if (entry.method != 0 && entry.method != 8) fail("uses unsupported compression method " + std::to_string(entry.method));
  if (entry.method == 0 && entry.packed != entry.size) fail("is stored with different packed and unpacked sizes");
  if (entry.method == 8 && entry.size > kMaxDeflateRatio * entry.packed + 64)
    fail("claims more bytes than deflate can expand " + std::to_string(entry.packed) + " bytes to");
  auto check_magic = [&](const uint8_t* p, size_t n) {
    if (magic.empty()) return;
    if (n < magic.size() || std::memcmp(p, magic.data(), magic.size()) != 0)
      throw Error(path + ": '" + entry.name + "' does not start with '" + std::string(magic) + "'");
  };
  std::vector<uint8_t> data;
  if (entry.method == 0) {
    check_magic(zip.data() + entry.data_at, entry.size);
    data.assign(zip.begin() + long(entry.data_at), zip.begin() + long(entry.data_at + entry.size));
  } else {
    z_stream z{};
    if (inflateInit2(&z, -MAX_WBITS) != Z_OK) fail("could not start zlib");
    struct End {
      z_stream* z;
      ~End() { inflateEnd(z); }
    } end{&z};
    z.next_in = const_cast<Bytef*>(zip.data() + entry.data_at);
    z.avail_in = static_cast<uInt>(entry.packed);
    // The first bytes alone, so the magic is checked before the stated size is allocated.
    uint8_t first[4096];
    z.next_out = first;
    z.avail_out = static_cast<uInt>(std::min<size_t>(sizeof first, entry.size));
    int rc = Z_OK;
    if (z.avail_out > 0) rc = inflate(&z, Z_SYNC_FLUSH);
    if (rc != Z_OK && rc != Z_STREAM_END) fail("does not inflate to its stated size");
    const size_t head = z.total_out;
    check_magic(first, head);
    // Reserved, not touched: memory grows with the bytes really inflated, so a member whose
    // stream breaks early costs what it gave.
    data.reserve(entry.size);
    data.assign(first, first + head);
    constexpr size_t kStep = size_t(1) << 20;
    while (rc != Z_STREAM_END && data.size() < entry.size) {
      const size_t at = data.size();
      data.resize(std::min(entry.size, at + kStep));
      z.next_out = data.data() + at;
      z.avail_out = static_cast<uInt>(data.size() - at);
      rc = inflate(&z, Z_SYNC_FLUSH);
      if (rc != Z_OK && rc != Z_STREAM_END) fail("does not inflate to its stated size");
      data.resize(z.total_out);
      if (rc == Z_OK && z.avail_in == 0 && data.size() < entry.size) fail("does not inflate to its stated size");
    }
    if (rc != Z_STREAM_END) {  // all the stated bytes: the stream must end here
      uint8_t extra = 0;
      z.next_out = &extra;
      z.avail_out = 1;
      rc = inflate(&z, Z_FINISH);
    }
    if (rc != Z_STREAM_END || z.total_out != entry.size) fail("does not inflate to its stated size");
  }
  if (uint32_t(crc32(0L, data.data(), static_cast<uInt>(data.size()))) != entry.crc) fail("fails its CRC-32 check");
  return data;
}

}  // namespace st
