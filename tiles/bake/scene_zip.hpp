// A minimal, bounds-checked zip reader (stored and deflated members) for Quake 3 .pk3
// archives, so that hostile archives never reach a parser that trusts them.
#pragma once
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace st {

struct ZipMember {
  std::string name;           // path inside the archive, as stored
  std::vector<uint8_t> data;  // uncompressed bytes
};

// The members of the archive `zip` whose lower-cased name ends with `suffix` (all if
// empty), in central-directory order. std::nullopt if there is no end-of-central-directory
// record (not a zip). Throws st::Error naming `path` when offsets or sizes point outside
// the archive, a member does not inflate to its stated size or fails its CRC-32, or uses a compression
// method other than stored (0) or deflate (8). Members are capped at 1 GiB.
std::optional<std::vector<ZipMember>> read_zip_members(const std::vector<uint8_t>& zip, const std::string& path,
                                                       const std::string& suffix);

}  // namespace st
