#include "tiles/core/pack_light_check.hpp"

#include "common/error.hpp"
#include "tiles/core/light.hpp"

namespace st {

void check_header_light(const PackHeader& h, const std::string& what) {
  if (const std::string why = LightSpace::check_array(h.light_kind, h.light); !why.empty())
    throw FormatError(what + " at byte 40: header: the light is not one a build makes: " + why);
}

}  // namespace st
