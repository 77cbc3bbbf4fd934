// Encoder dispatch by format tag, and the MH / MMH entry points (the quadtree layout is
// mh_quadtree_layout.cpp, MMH's merge plan mmh_merge.cpp; DAG-MH is dagmh_encode.cpp).
#include "tiles/encode/encode.hpp"

#include "common/error.hpp"
#include "tiles/encode/mh_quadtree_layout.hpp"
#include "tiles/encode/mmh_merge.hpp"
#include "tiles/encode/vsdag_encode.hpp"

namespace st {

std::vector<uint8_t> encode_mh(const Hierarchy& h) {
  const mhq::FlatTree t = mhq::flatten(h, /*need_intervals=*/false);
  return mhq::serialize(t, mhq::EmitPlan{});
}

std::vector<uint8_t> encode_mmh(const Hierarchy& h) {
  const mhq::FlatTree t = mhq::flatten(h, /*need_intervals=*/true);
  return mhq::serialize(t, mhq::plan_mmh(t, mhq::MergeOptions{}));
}

std::vector<uint8_t> encode(const Hierarchy& h, Encoding e) {
  switch (e) {
    case Encoding::mh: return encode_mh(h);
    case Encoding::mmh: return encode_mmh(h);
    case Encoding::dagmh: return encode_dagmh(h);
    case Encoding::vsdag: return encode_vsdag(h, VsdagOptions{});
  }
  throw Error("encoding '" + to_string(e) + "' is not available in this build");
}

}  // namespace st
