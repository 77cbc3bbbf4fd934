// The one check of a pack header's light shared by every reader that evaluates a map: the
// pack reader (a file) and the client (the header a server's MapInfo carries), so a
// light one of them refuses is refused by both.
#pragma once
#include <string>

#include "tiles/core/pack_format.hpp"

namespace st {

// The light (header bytes 40-183) is one a build makes (LightSpace::check_array: finite,
// coordinates within 1e18, orthonormal axes, 0 <= near < far); else st::FormatError
// "<what> at byte 40: header: the light is not one a build makes: <why>". Kept out of
// PackHeader::parse so that inspect can still show a damaged header.
void check_header_light(const PackHeader& h, const std::string& what);

}  // namespace st
