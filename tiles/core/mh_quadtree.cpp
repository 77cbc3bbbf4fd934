// MH quadtree (MH §3.2) and MMH openers: entry points declared in tiles/core/encoding.hpp.
// The format is drawn in tiles/core/mh_quadtree_format.hpp and tiles/core/MHQUAD.md; the
// encoders are in tiles/encode/encode.cpp.
#include "tiles/core/encoding.hpp"
#include "tiles/core/mh_quadtree_reader.hpp"

namespace st {

// Opens MH and, by its magic, MMH buffers too (encoding.hpp); open_mmh takes MMH only.
std::unique_ptr<Evaluator> open_mh(std::span<const uint8_t> bytes) {
  const bool mmh = bytes.size() >= 4 && st::load_le<uint32_t>(bytes.data()) == mhq::kMagicMmh;
  return mhq::make_evaluator(bytes, mhq::validate(bytes, /*relative=*/mmh));
}

std::unique_ptr<Evaluator> open_mmh(std::span<const uint8_t> bytes) {
  return mhq::make_evaluator(bytes, mhq::validate(bytes, /*relative=*/true));
}

}  // namespace st
