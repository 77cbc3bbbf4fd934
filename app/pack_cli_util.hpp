// Helpers shared by the pack subcommands (inspect, verify, export).
#pragma once
#include <cstdint>
#include <string>

#include "tiles/core/pack_reader.hpp"

namespace st::cli {

std::string feature_names(uint32_t flags);
// "X,Y,W,H" -> region; throws st::Error naming the option.
struct Rect {
  uint64_t x = 0, y = 0, w = 0, h = 0;
};
Rect parse_rect(const std::string& option, const std::string& text);
// The region a pack was built for ("region" build parameter), or the whole map.
Rect built_region(const PackReader& reader);

}  // namespace st::cli
