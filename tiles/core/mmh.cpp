// MMH (merged MH quadtree): entry points declared in tiles/core/encoding.hpp. Merging is
// planned in mmh_merge.cpp; the layout and format are the MH quadtree's
// (mh_quadtree_format.hpp) with relative values and node-local offset shifts.
#include "tiles/core/encoding.hpp"
#include "tiles/core/mh_quadtree_layout.hpp"
#include "tiles/core/mh_quadtree_reader.hpp"
#include "tiles/core/mmh_merge.hpp"

namespace st {

std::vector<uint8_t> encode_mmh(const Hierarchy& h) {
  const mhq::FlatTree t = mhq::flatten(h, /*need_intervals=*/true);
  return mhq::serialize(t, mhq::plan_mmh(t, mhq::MergeOptions{}));
}

std::unique_ptr<Evaluator> open_mmh(std::span<const uint8_t> bytes) {
  return mhq::make_evaluator(bytes, mhq::validate(bytes, /*relative=*/true));
}

}  // namespace st
