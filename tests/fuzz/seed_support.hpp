// Valid inputs for the seed corpora, made by the project's own encoders: random interval
// fields -> build_hierarchy -> encode (tiles), -> write_pack (packs), and frames of every
// message type (proto). Deterministic: the same seed number gives the same bytes.
#pragma once
#include <cstdint>
#include <random>
#include <vector>

#include "tests/fuzz/fuzz_harness.hpp"
#include "tiles/core/encoding.hpp"
#include "tiles/encode/hierarchy.hpp"
#include "tiles/core/interval.hpp"

namespace st::fuzz {

// Interval field kinds: flat, noise, blocks with lit (no-hit) regions, a slope with
// tolerance; they give hierarchies with constant subtrees, deep leaves and both.
enum class FieldKind : int { flat = 0, noise = 1, blocks = 2, slope = 3 };
inline constexpr int kFieldKinds = 4;

// A 2^level square field of the given kind (lo <= hi, finite, some texels kLitDepth).
IntervalTile random_field(uint32_t level, FieldKind kind, std::mt19937_64& rng);

// Hierarchies of small random fields (levels 0..max_level, every kind).
std::vector<Hierarchy> seed_hierarchies(uint32_t max_level, uint64_t seed);

// Encoded tiles of `e` for seed_hierarchies(max_level, seed).
std::vector<Bytes> encoded_tiles(Encoding e, uint32_t max_level, uint64_t seed);

// Whole pack files (write_pack to a temporary file, read back) of small maps, for each
// encoding, with the default tile bound and a small one (so index tiles appear).
std::vector<Bytes> pack_files(uint64_t seed);

// One frame of every message type of protocol version 1 (each a whole frame: header +
// payload), with request ids and flags a real peer would use; all fit 64 KiB frames.
std::vector<Bytes> message_frames(uint64_t seed);

}  // namespace st::fuzz
