// Reader of MH quadtree and MMH buffers (tiles/core/mh_quadtree_format.hpp): one full
// validation pass at open, then lookups that trust only what was validated.
// Internal to tiles/core; callers use open_mh / open_mmh (encoding.hpp).
#pragma once
#include <array>
#include <cstdint>
#include <memory>
#include <span>

#include "tiles/core/evaluator.hpp"
#include "tiles/core/mh_quadtree_format.hpp"

namespace st::mhq {

struct TreeInfo {
  bool relative = false;  // MMH
  bool root_leaf = false;
  uint32_t levels = 0;
  uint32_t node_count = 0;
  std::array<uint8_t, kMaxLevels> shift{};
  size_t tree_offset = 0;
  uint64_t words = 0;
};

// Validates the whole buffer (header fields, every node reached from the root: in
// bounds, kinds consistent where blocks are shared, offsets strictly forward, no node
// below the finest level, finite floats, zero padding, no trailing bytes, node count).
// Throws st::FormatError "MH quadtree: <field> at byte <offset>: <problem>".
// `relative` selects the MMH format (magic "STMM") instead of MH ("STMH").
TreeInfo validate(std::span<const uint8_t> bytes, bool relative);

// The evaluator over a validated buffer; references `bytes` (kept alive by the caller).
std::unique_ptr<Evaluator> make_evaluator(std::span<const uint8_t> bytes, const TreeInfo& info);

}  // namespace st::mhq
