// Map resolutions as users write them: "4096", "16k", "1m" (powers of two, <= 2^20).
#pragma once
#include <cstdint>
#include <string>

namespace st {

// Returns the level L (side 2^L). Throws st::Error naming the text when it is not a
// power of two up to 1m.
uint32_t parse_resolution(const std::string& text);

}  // namespace st
