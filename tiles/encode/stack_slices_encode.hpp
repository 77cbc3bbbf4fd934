// The per-slice form of a stack cell (tiles/core/stack_slices.hpp, MHOCT.md "Per-slice
// cells"): each slice's square of the cell built as its own 2D hierarchy (MH §3.1) and
// encoded as DAG-MH or MMH, whichever deflates smaller (as a 2D pack's mixed tiles), and
// the choice between that and the cell's MH octree tile.
#pragma once
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "tiles/core/interval.hpp"
#include "tiles/encode/plane_fit.hpp"

namespace st {

// Which form a stack build gives its cells: the octree always (the format before per-slice
// cells), per-slice tiles always (tests), or per cell the one whose zlib stream (level 6,
// as the pack stores it) is shorter and fits the tile bound (the default).
enum class StackCells : uint8_t { octree, slices, smaller };
StackCells parse_stack_cells(const std::string& text);  // "octree" | "slices" | "smaller"; throws st::Error

// The "STSL" buffer of a cell whose slices' squares (each 2^m a side, row-major) are
// `slices` (at most 2^j of them; the entries past them are constant kLitDepth). A slice
// whose square stores nothing below its root is a constant entry; equal buffers are
// stored once. Throws st::Error when the result exceeds the format's 32-bit size.
// `planes` (optional): a slice's tile may also be a plane tile ("STPN", tiles/core/
// PLANES.md) over DAG-MH or MMH, the same candidates a 2D pack with plane tiles weighs
// (TileCodec::with_planes over TileCodec::dagmh_or_mmh, exhaustive), kept where its zlib
// stream (of its packed form, as a grouped cell stores it) is shorter. Null: DAG-MH or
// MMH only (the buffers before plane slices, byte for byte). Both ways each slice is
// encoded by one TileCodec (TileCodec::encode_smaller). `plain` (with `planes`, optional):
// this cell's buffer without planes (encode_slice_tiles(slices, m, j)); its constant slices
// and the tiles too small for a plane tile to store smaller (at most 80 zlib bytes,
// stack_slices_encode.cpp) are taken from it as they are, only the others fitted.
std::vector<uint8_t> encode_slice_tiles(std::span<const IntervalTile> slices, uint32_t m, uint32_t j,
                                        const PlaneFitOptions* planes = nullptr, std::span<const uint8_t> plain = {});

// The grouped stored form ("STSP", stack_slices.hpp) of an STSL buffer: the same bytes
// permuted so like lies with like, the same size; ungroup_slice_tiles gives `stsl` back
// (checked here on every call). A plane slice ("STPN") is stored whole in its packed form
// ("STPL" with predicted labels, plane_pack.hpp; `predict_plane_labels` false: "STPQ")
// among the heads. Anything else (an octree tile, a buffer that does not group) comes back
// unchanged. Used by the stack pack writer on every per-slice cell.
std::vector<uint8_t> group_slice_tiles(std::span<const uint8_t> stsl, bool predict_plane_labels = true);

}  // namespace st
