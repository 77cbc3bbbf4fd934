// TileCodec::with_planes (tile_cut.hpp): each tile's encoding with and without plane blocks
// (plane_fit.hpp, tiles/core/PLANES.md), the one that stores smaller kept.
#include <algorithm>
#include <optional>

#include "common/error.hpp"
#include "tiles/encode/plane_fit.hpp"
#include "tiles/encode/tile_cut.hpp"
#include "tiles/core/pack_format.hpp"
#include "tiles/core/plane_pack.hpp"
#include "tiles/core/plane_tile.hpp"

namespace st {

TileCodec TileCodec::with_planes(TileCodec base, uint32_t tile_bytes, const PlaneFitOptions& fit) {
  TileCodec c = base;
  using Fn = std::function<std::vector<uint8_t>(const Hierarchy&)>;
  c.alternative = nullptr;
  c.choose = nullptr;
  c.encode = [enc = base.encode, alt = base.alternative, choose = base.choose, tile_bytes, fit](const Hierarchy& h) {
    // Candidates: the base encodings of h, and of h without its plane blocks behind them.
    std::optional<std::vector<uint8_t>> best;
    size_t best_z = SIZE_MAX;
    std::optional<Error> failure;
    auto offer = [&](std::vector<uint8_t> bytes) {
      const bool fits = bytes.size() <= tile_bytes, best_fits = best && best->size() <= tile_bytes;
      if (best_fits && !fits) return;
      size_t z = fits ? zlib_compress(bytes, kEncodingChoiceZlibLevel).size() : bytes.size();
      if (fits && fit.packed && is_plane_buffer(bytes)) {  // as the pack will store it
        const std::vector<uint8_t> packed = pack_plane_tile(bytes, nullptr, fit.predicted);
        if (!packed.empty()) z = std::min(z, zlib_compress(packed, kEncodingChoiceZlibLevel).size());
      }
      if (!best || (fits && !best_fits) || z < best_z) best = std::move(bytes), best_z = z;
    };
    auto attempt = [&](const Fn& f, const Hierarchy& tree, const PlaneSplit* split) {
      if (!f) return;
      try {
        std::vector<uint8_t> inner = f(tree);
        offer(split ? wrap_planes(split->planes, h.depth, inner, split->labelled) : std::move(inner));
      } catch (const Error& e) {
        if (!failure) failure = e;
      }
    };
    // base.choose, as tile_cut.cpp honours it: a sure guess encodes only that encoding (the
    // other too where the guessed one fails or does not fit tile_bytes); unsure: both.
    const int pick = alt && choose ? choose(h) : 0;
    auto both = [&](const Hierarchy& tree, const PlaneSplit* split) {
      const Fn& first = pick > 0 ? alt : enc;
      const Fn& second = pick > 0 ? enc : alt;
      const bool fitted_before = best && best->size() <= tile_bytes;
      attempt(first, tree, split);
      const bool fitted = best && best->size() <= tile_bytes;
      if (pick == 0 || (!fitted_before && !fitted)) attempt(second, tree, split);
    };
    both(h, nullptr);
    uint64_t valued = 0, zero = 0;
    for (const auto& level : h.levels)
      for (const HNode& n : level)
        if (n.has_value) ++valued, zero += n.lo == n.hi;
    if (valued == 0 || double(zero) < fit.min_zero_width_share * double(valued)) {
      if (!best) throw *failure;
      return std::move(*best);
    }
    const PlaneSplit split = fit_planes(h, fit);
    if (!split.planes.empty() || !split.labelled.empty()) both(split.pruned, &split);
    if (!best) throw *failure;
    return std::move(*best);
  };
  c.open = [open = base.open](std::span<const uint8_t> bytes) {
    if (is_plane_buffer(bytes)) return open_plane_tile(bytes, open);
    return open(bytes);
  };
  return c;
}

}  // namespace st
