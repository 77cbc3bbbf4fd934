// The encodings of a hierarchy (ARCHITECTURE.md "Encodings"): each is one self-contained byte
// buffer with offsets, no pointers, read in place by its evaluator (the same bytes later
// sit in a pack, on the wire and in a GPU cache slot).
//
// Encoders (tiles/encode/encode.hpp) take a Hierarchy and return the buffer. Openers
// validate the whole buffer once (every offset, count and length in range; trailing
// bytes rejected) and throw st::FormatError naming the field and byte offset otherwise;
// after a successful open, lookups never read out of bounds. The returned evaluator
// references `bytes`: the caller keeps them alive and unchanged.
#pragma once
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "tiles/core/evaluator.hpp"

namespace st {

enum class Encoding : uint8_t { mh = 0, mmh = 1, dagmh = 2, vsdag = 3 };  // format constant: packs store it
inline constexpr Encoding kLastEncoding = Encoding::vsdag;

std::string to_string(Encoding e);
Encoding parse_encoding(const std::string& name);  // "mh" | "mmh" | "dagmh" | "vsdag"; throws st::Error

// Per-encoding openers (implemented in their own files).
std::unique_ptr<Evaluator> open_mh(std::span<const uint8_t> bytes);     // MH and MMH buffers
std::unique_ptr<Evaluator> open_mmh(std::span<const uint8_t> bytes);
std::unique_ptr<Evaluator> open_dagmh(std::span<const uint8_t> bytes);
std::unique_ptr<Evaluator> open_vsdag(std::span<const uint8_t> bytes);  // voxel shadow DAG (VSDAG.md)

// Whether `bytes` start with the MMH magic "STMM": a DAG-MH pack's tile may be an MMH
// buffer where that stored smaller (tiles/PACK.md "Mixed tiles").
bool is_mmh_buffer(std::span<const uint8_t> bytes);

// Dispatch by tag. Encoding::dagmh opens an MMH buffer as MMH (is_mmh_buffer), so every
// reader of a DAG-MH pack's tiles takes its mixed tiles.
std::unique_ptr<Evaluator> open_encoded(Encoding e, std::span<const uint8_t> bytes);

}  // namespace st
