// MH quadtree (MH §3.2): entry points declared in tiles/core/encoding.hpp. The format is
// drawn in tiles/core/mh_quadtree_format.hpp and tiles/core/MHQUAD.md.
#include "tiles/core/encoding.hpp"
#include "tiles/core/mh_quadtree_layout.hpp"
#include "tiles/core/mh_quadtree_reader.hpp"

namespace st {

std::vector<uint8_t> encode_mh(const Hierarchy& h) {
  const mhq::FlatTree t = mhq::flatten(h, /*need_intervals=*/false);
  return mhq::serialize(t, mhq::EmitPlan{});
}

std::unique_ptr<Evaluator> open_mh(std::span<const uint8_t> bytes) {
  return mhq::make_evaluator(bytes, mhq::validate(bytes, /*relative=*/false));
}

}  // namespace st
