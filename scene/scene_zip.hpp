// The zip reader for Quake 3 .pk3 archives: minizip (Debian libminizip) reads the archive
// from memory; this file adds the limits that keep a hostile archive bounded (member size,
// entry count, deflate ratio, compression method) and turns every failure into one
// st::Error line naming the archive.
#pragma once
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace st {

// One member as its central-directory entry describes it.
struct ZipEntry {
  std::string name;  // path inside the archive, as stored
  uint16_t method = 0;
  uint32_t crc = 0;
  size_t packed = 0, size = 0;
  uint64_t directory_at = 0, index = 0;  // where minizip finds the entry again
};

// Most entries an archive may list (a Quake 3 pk3 holds hundreds to a few thousand).
constexpr size_t kZipMaxEntries = size_t(1) << 20;

// The entries of the archive `zip` whose lower-cased name ends with `suffix` (all if
// empty), in central-directory order. std::nullopt if there is no end-of-central-directory
// record (not a zip). Throws st::Error naming `path` when the directory cannot be read
// (offsets or sizes outside the archive, more than kZipMaxEntries entries), a member
// claims more than 1 GiB or more than its packed bytes can give (stored: exactly them;
// deflate: 1032 times them), is encrypted, or uses a method other than stored or deflate:
// what extract_zip allocates is bounded by the archive's own size.
std::optional<std::vector<ZipEntry>> list_zip(const std::vector<uint8_t>& zip, const std::string& path,
                                              const std::string& suffix);

// The uncompressed bytes of `entry`. Throws st::Error naming `path` and the member when
// it does not inflate to its stated size, fails its CRC-32, or uses a compression method
// other than stored (0) or deflate (8).
// `magic`, when given, is what the member must start with: it is checked on the first
// inflated bytes, before the member's stated size is allocated or the rest inflated (a
// member of 1 GiB that is not what the caller reads costs a few KiB), and a mismatch is an
// st::Error naming the member.
std::vector<uint8_t> extract_zip(const std::vector<uint8_t>& zip, const std::string& path, const ZipEntry& entry,
                                 std::string_view magic = {});

}  // namespace st
