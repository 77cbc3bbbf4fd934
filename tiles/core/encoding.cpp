// Dispatch of the encodings by their format tag (encoding.hpp). Each case may only name
// an encoder that is linked into this build: the others answer with a clear st::Error.
#include "tiles/core/encoding.hpp"

#include "common/bytes.hpp"
#include "common/error.hpp"
#include "tiles/core/mh_quadtree_format.hpp"
#include "tiles/core/plane_tile.hpp"

namespace st {

std::string to_string(Encoding e) {
  switch (e) {
    case Encoding::mh: return "mh";
    case Encoding::mmh: return "mmh";
    case Encoding::dagmh: return "dagmh";
    case Encoding::vsdag: return "vsdag";
  }
  return "encoding#" + std::to_string(int(e));
}

Encoding parse_encoding(const std::string& name) {
  if (name == "mh") return Encoding::mh;
  if (name == "mmh") return Encoding::mmh;
  if (name == "dagmh") return Encoding::dagmh;
  if (name == "vsdag") return Encoding::vsdag;
  throw Error("unknown encoding '" + name + "' (expected mh, mmh, dagmh or vsdag)");
}

namespace {
[[noreturn]] void not_built(Encoding e) {
  throw Error("encoding '" + to_string(e) + "' is not available in this build");
}
}  // namespace

bool is_mmh_buffer(std::span<const uint8_t> bytes) {
  return bytes.size() >= 4 && load_le<uint32_t>(bytes.data()) == mhq::kMagicMmh;
}

std::unique_ptr<Evaluator> open_encoded(Encoding e, std::span<const uint8_t> bytes) {
  // A plane tile (tiles/core/PLANES.md) of an MH, MMH or DAG-MH pack holds that encoding's buffer.
  if (e != Encoding::vsdag && is_plane_buffer(bytes))
    return open_plane_tile(bytes, [e](std::span<const uint8_t> inner) { return open_encoded(e, inner); });
  if (e == Encoding::dagmh && is_mmh_buffer(bytes)) return open_mmh(bytes);  // a mixed tile
  switch (e) {
    case Encoding::mh: return open_mh(bytes);
    case Encoding::mmh: return open_mmh(bytes);
    case Encoding::dagmh: return open_dagmh(bytes);
    case Encoding::vsdag: return open_vsdag(bytes);
  }
  not_built(e);
}

}  // namespace st
