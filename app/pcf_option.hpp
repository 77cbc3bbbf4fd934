// The PCF kernel side every command takes (--pcf): the public API's one unit
// (client.hpp "PCF"): odd, 1..9; anything else is refused in one line.
#pragma once
#include <cstdint>
#include <string>

#include "common/error.hpp"
#include "shadowtile/client.hpp"

namespace st::cli {

inline uint32_t checked_pcf_side(const std::string& option, uint32_t side, uint32_t least = 1) {
  if (!client::pcf_side_valid(side) || side < least)
    throw Error(option + ": a PCF kernel side is odd, " + std::to_string(least) + ".." +
                std::to_string(client::kMaxPcfSide) + " (" + (least == 1 ? "1: one tap, " : "") + "3: 3x3, 5: 5x5, ...), got " +
                std::to_string(side));
  return side;
}

}  // namespace st::cli
