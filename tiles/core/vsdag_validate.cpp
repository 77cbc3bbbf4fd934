// Voxel shadow DAG validation (VSDAG.md "Validation"): hostile input is the normal case.
// Section extents come from the counts in 64-bit arithmetic and must equal the header's
// offsets and the buffer's length; every node is parsed, every reference followed once
// per node, and each node must be reached at exactly one level, so no walk can leave its
// section or read a z-node as an inner node.
#include <string>
#include <vector>

#include "common/error.hpp"
#include "tiles/core/interval.hpp"
#include "tiles/core/vsdag_view.hpp"

namespace st::vsdag {
namespace {

[[noreturn]] void fail(const std::string& field, uint64_t offset, const std::string& what) {
  throw FormatError("vsdag: " + field + " at byte " + std::to_string(offset) + ": " + what);
}

void expect(const char* name, size_t offset, uint64_t value, uint64_t expected) {
  if (value != expected)
    fail(name, offset, "is " + std::to_string(value) + ", expected " + std::to_string(expected));
}

}  // namespace

View validate(std::span<const uint8_t> bytes) {
  if (bytes.size() < sizeof(Header))
    fail("header", 0, "buffer of " + std::to_string(bytes.size()) + " bytes is shorter than the 64-byte header");
  Header h;
  std::memcpy(&h, bytes.data(), sizeof h);
  expect("magic", offsetof(Header, magic), h.magic, kMagic);
  expect("version", offsetof(Header, version), h.version, kVersion);
  expect("header_bytes", offsetof(Header, header_bytes), h.header_bytes, sizeof(Header));
  if (h.xy_bits > kMaxLevel) fail("xy_bits", offsetof(Header, xy_bits), "exceeds 20");
  if (h.z_bits < kMinZBits || h.z_bits > kMaxZBits)
    fail("z_bits", offsetof(Header, z_bits), "is " + std::to_string(h.z_bits) + ", expected 3..20");
  const Shape s = Shape::of(h.xy_bits, h.z_bits);
  expect("grid_xy_bits", offsetof(Header, grid_xy_bits), h.grid_xy_bits, s.grid_xy_bits);
  expect("grid_z_bits", offsetof(Header, grid_z_bits), h.grid_z_bits, s.grid_z_bits);
  expect("inner_levels", offsetof(Header, inner_levels), h.inner_levels, s.levels);
  if (h.leaf_count >= kMaxCount) fail("leaf_count", offsetof(Header, leaf_count), "exceeds 2^30");
  if (h.node_words >= kMaxCount) fail("node_words", offsetof(Header, node_words), "exceeds 2^30");
  const uint64_t leaf_off = sizeof(Header), grid_off = leaf_off + 8 * uint64_t(h.leaf_count);
  const uint64_t node_off = grid_off + 4 * uint64_t(s.grid_cells()), end = node_off + 4 * uint64_t(h.node_words);
  expect("leaf_offset", offsetof(Header, leaf_offset), h.leaf_offset, leaf_off);
  expect("grid_offset", offsetof(Header, grid_offset), h.grid_offset, grid_off);
  expect("node_offset", offsetof(Header, node_offset), h.node_offset, node_off);
  expect("total_bytes", offsetof(Header, total_bytes), h.total_bytes, end);
  expect("reserved0", offsetof(Header, reserved0), h.reserved0, 0);
  expect("reserved1", offsetof(Header, reserved1), h.reserved1, 0);
  if (end != bytes.size())
    fail("sections", end, "end at byte " + std::to_string(end) + " but the buffer has " +
                              std::to_string(bytes.size()) + " bytes (truncated or trailing bytes)");

  View v;
  v.shape = s;
  v.leaves = bytes.data() + leaf_off;
  v.grid = bytes.data() + grid_off;
  v.nodes = bytes.data() + node_off;
  v.leaf_count = h.leaf_count, v.node_words = h.node_words;
  auto node_at = [&](uint32_t w) { return node_off + 4 * uint64_t(w); };

  // Parse the node section: every word belongs to exactly one node (mask + references).
  // level_of[w] = 1 + the level a node starting at w was reached at; 0 = not yet; the
  // words inside a node hold kInside.
  constexpr uint8_t kInside = 0xFF, kUnreached = 0xFE;
  std::vector<uint8_t> level_of(h.node_words, kInside);
  for (uint32_t w = 0; w < h.node_words;) {
    const uint32_t mask = v.node_word(w);
    if (mask >> 16) fail("node mask", node_at(w), "bits 16-31 are not zero");
    for (uint32_t c = 0; c < 8; ++c)
      if (((mask >> (2 * c)) & 3) == 3) fail("node mask", node_at(w), "child state 3 is undefined");
    const uint64_t size = 1 + uint64_t(bit_count(mixed_bits(mask)));
    if (w + size > h.node_words) fail("node", node_at(w), "references run past the node section");
    level_of[w] = kUnreached;
    w += uint32_t(size);
  }

  std::vector<uint8_t> leaf_used(h.leaf_count, 0);
  // Depth-first from the grid; each node checked once (at its first arrival).
  struct Item { uint32_t w; uint32_t level; };
  std::vector<Item> stack;
  auto arrive = [&](uint32_t w, uint32_t level, uint64_t from) {
    if (w >= h.node_words || level_of[w] == kInside)
      fail("reference", from, "word " + std::to_string(w) + " is not the start of a node");
    if (level_of[w] == kUnreached) {
      level_of[w] = uint8_t(level);
      stack.push_back({w, level});
    } else if (level_of[w] != level) {
      fail("reference", from, "node at word " + std::to_string(w) + " is reached at two levels");
    }
  };
  for (uint32_t c = 0; c < s.grid_cells(); ++c) {
    const uint32_t cell = v.grid_word(c), st = cell >> kStateShift, at = uint32_t(grid_off + 4 * uint64_t(c));
    if (st == 3) fail("grid cell", at, "state 3 is undefined");
    if (st != kMixed) {
      if (cell & kIndexMask) fail("grid cell", at, "a lit or shadowed cell has a reference");
      continue;
    }
    arrive(cell & kIndexMask, 0, at);
  }
  while (!stack.empty()) {
    const Item it = stack.back();
    stack.pop_back();
    const uint32_t mask = v.node_word(it.w);
    uint32_t r = it.w + 1;
    for (uint32_t c = 0; c < 8; ++c) {
      const uint32_t st = (mask >> (2 * c)) & 3;
      if (it.level < s.levels) {
        // Slots of an axis the level does not split stay shadowed with no reference.
        const bool used = ((c & 3) == 0 || (s.split[it.level] & kSplitXy)) && (c < 4 || (s.split[it.level] & kSplitZ));
        if (!used && st != kShadow) fail("node mask", node_at(it.w), "slot " + std::to_string(c) + " is not used at this level");
      }
      if (st != kMixed) continue;
      const uint32_t ref = v.node_word(r);
      if (it.level == s.levels) {
        if (ref >= h.leaf_count) fail("leaf reference", node_at(r), "leaf " + std::to_string(ref) + " out of range");
        leaf_used[ref] = 1;
      } else {
        if (ref >= it.w) fail("reference", node_at(r), "does not point to an earlier node");
        arrive(ref, it.level + 1, node_at(r));
      }
      ++r;
    }
  }
  for (uint32_t w = 0; w < h.node_words; ++w)
    if (level_of[w] == kUnreached) fail("node", node_at(w), "is not reachable from the grid");
  for (uint32_t i = 0; i < h.leaf_count; ++i)
    if (!leaf_used[i]) fail("leaf", leaf_off + 8 * uint64_t(i), "is not referenced");
  return v;
}

}  // namespace st::vsdag
