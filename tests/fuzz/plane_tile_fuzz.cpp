// libFuzzer harness for plane tiles (tiles/core/PLANES.md, plane_tile.hpp) in a DAG-MH
// pack's tile slot: plane blocks over an inner DAG-MH or MMH buffer. Contract: the opener
// validates the header, the plane table, every block record and labelled block and the inner buffer, or throws
// st::FormatError; a buffer it accepts answers every lookup without reading out of bounds,
// and PCF equals the average of its single lookups (evaluator_probe.hpp). A packed plane
// tile ("STPQ", or "STPL" with predicted labels: plane_pack.hpp, how packs store them) unpacks in place or throws
// st::FormatError, and one whose unpacked bytes open packs back to the very input (the
// packed form is canonical); the seeds hold both forms.
#include <algorithm>
#include <span>
#include <vector>

#include "common/error.hpp"
#include "tests/fuzz/evaluator_probe.hpp"
#include "tests/fuzz/fuzz_harness.hpp"
#include "tiles/encode/encode.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/encode/plane_fit.hpp"
#include "tiles/core/encoding.hpp"
#include "tiles/core/pack_format.hpp"
#include "tiles/core/plane_pack.hpp"

namespace {

// A tile of `level` whose texels lie on a few slanted planes (open geometry: hi = lo), the
// field plane tiles are made for: one plane, two halves (labelled blocks on their edge), a
// plane with a step of holes, and facets: three planes of its own in every 8x8 block (the
// labelled blocks whose planes are grown from seeds, PlaneFitOptions::grow_labels), or six
// (wide labelled blocks).
st::IntervalTile planar_tile(uint32_t level, int kind) {
  const uint32_t side = 1u << level;
  st::IntervalTile t{level, 0, 0, side, side, {}};
  t.data.resize(size_t(side) * side);
  for (uint32_t y = 0; y < side; ++y)
    for (uint32_t x = 0; x < side; ++x) {
      double d = 0.3 + 0.0011 * x + 0.0007 * y;
      if (kind == 1 && 2 * x + y >= side) d = 0.6 - 0.0013 * x + 0.0002 * y;  // a slanted edge
      if (kind == 2 && (x / 8 + y / 8) % 3 == 0) d = 1.0;  // no hit
      if (kind == 4) {
        const uint32_t u = x % 8, v = y % 8, facet = u + v < 6 ? 0 : u > v ? 1 : 2;
        const double sx[3] = {0.0011, -0.0023, 0.0004}, sy[3] = {0.0007, 0.0015, -0.0031};
        d = 0.3 + 0.01 * double(x / 8 + 3 * (y / 8)) + 0.05 * facet + sx[facet] * x + sy[facet] * y;
      }
      if (kind == 5) {  // six facets a block: wide labelled blocks (3-bit labels)
        const uint32_t facet = (x % 8) / 3 + 3 * ((y % 8) / 4);
        d = 0.2 + 0.01 * double(x / 8 + 3 * (y / 8)) + 0.07 * facet + 0.0003 * facet * x - 0.0002 * facet * y;
      }
      const float f = float(d);
      t.at(x, y) = {f, kind == 3 ? f + 0.01f : f};
    }
  return t;
}

}  // namespace

std::vector<st::fuzz::Bytes> st::fuzz::seeds() {
  std::vector<Bytes> out;
  for (uint32_t level : {3u, 4u, 5u})
    for (int kind = 0; kind < 6; ++kind) {
      const st::PlaneSplit s = st::fit_planes(st::build_hierarchy(planar_tile(level, kind)), st::PlaneFitOptions{3, 1, 10});
      if (s.planes.empty() && s.labelled.empty()) continue;
      for (st::Encoding e : {st::Encoding::dagmh, st::Encoding::mmh}) {
        out.push_back(st::wrap_planes(s.planes, level, st::encode(s.pruned, e), s.labelled));
        const std::vector<std::uint8_t> stpn = out.back();
        for (bool predict : {false, true}) {  // "STPQ" and "STPL"
          std::vector<std::uint8_t> packed = st::pack_plane_tile(stpn, nullptr, predict);
          if (!packed.empty()) out.push_back(std::move(packed));
        }
      }
    }
  return out;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::vector<std::uint8_t> bytes(data, data + size);  // exact size: ASan sees overreads
  const bool packed = st::is_packed_plane_tile(bytes);
  const bool predicted = st::packed_plane_tile_features(bytes) & st::kFeaturePredictedPlaneLabels;
  if (packed) {
    try {
      st::unpack_plane_tile(bytes);
    } catch (const st::FormatError&) {
      return 0;
    }
  }
  std::unique_ptr<st::Evaluator> ev;
  try {
    ev = st::open_encoded(st::Encoding::dagmh, std::span<const std::uint8_t>(bytes.data(), bytes.size()));
  } catch (const st::FormatError&) {
    return 0;
  }
  FUZZ_CHECK(ev != nullptr);
  if (packed) {
    const std::vector<std::uint8_t> again = st::pack_plane_tile(bytes, nullptr, predicted);
    FUZZ_CHECK(again.size() == size && std::equal(again.begin(), again.end(), data));
  }
  st::fuzz::note_accepted();
  st::fuzz::probe_evaluator(*ev, st::fuzz::input_hash(data, size));
  return 0;
}
