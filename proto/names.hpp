// Text fields on the wire and their rules (PROTOCOL.md §4.2). Map names are chosen by
// clients and used by the server to find a pack: they are restricted so that a client can
// never name a path ("../x", "/etc", "a/b", "C:", "", hidden files, option-like names).
#pragma once
#include <cstddef>
#include <string>
#include <string_view>

#include "proto/status.hpp"

namespace st::proto {

inline constexpr std::size_t kMaxMapNameBytes = 64;      // FORMAT CONSTANT
inline constexpr std::size_t kMaxLabelBytes = 64;        // client/server/counter names
inline constexpr std::size_t kMaxErrorMessageBytes = 1024;

// Map and counter names: 1..64 bytes of [A-Za-z0-9._-], not starting with '.' or '-'.
// Fails with bad_map_name naming the offending byte.
Status validate_map_name(std::string_view name);
bool is_valid_map_name(std::string_view name);

// Free text (peer names, error messages): at most max_bytes, no control bytes
// (0x00-0x1F, 0x7F) so it always prints as one line and carries no terminal escapes.
// Bytes >= 0x80 pass (UTF-8 is not validated). Fails with invalid_field.
Status validate_text(std::string_view text, std::size_t max_bytes, const char* field);

// Makes any text valid free text: control bytes become '?', and it is cut to max_bytes
// (at a byte boundary; a cut UTF-8 sequence is harmless since UTF-8 is not validated).
// For forwarding exception messages (st::Error::what()) into Error and TileError frames.
// (Text from files shown on a terminal or in a log is escaped instead: common/text.hpp.)
std::string sanitize_text(std::string_view text, std::size_t max_bytes);

}  // namespace st::proto
