// DAG-MH buffer validation: open_dagmh checks the whole buffer once, so that lookups
// need no bounds checks (the safety argument is in dagmh_traverse.hpp).
#pragma once
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "tiles/core/dagmh_traverse.hpp"
#include "tiles/core/evaluator.hpp"

namespace st::dagmh {

// Checks every header field, section length and offset, every inner node (flags, child
// references in range and strictly forward, value offsets equal to the subtree value
// counts, reachable from the root), every treelet's padding bits, every chunk (factor
// bits, multipliers inside the section, mask bits past the last value clear) and the
// skip table (recomputed from the DAG), and rejects trailing bytes. Throws
// st::FormatError("dagmh: <field> at byte <offset>: <what>") on the first violation.
//
// A tile with kFlagDictionary (references into a pack dictionary) needs `dict`, the dictionary whose
// CRC-32 its header names; its references must then be the tile's own nodes and treelets
// or the dictionary's (node starts, in range). A tile without the flag ignores `dict`.
class Dictionary;
View validate(std::span<const uint8_t> bytes, const Dictionary* dict = nullptr);

// A validated pack dictionary (DAGMH.md "Dictionary"). Owns its bytes; keeps each node
// start's value count (4 bytes per node word) so tiles are checked against it in linear
// time. open() checks the header, every node (flags, extent, references in range and
// strictly forward, value offsets) and treelet padding, and throws
// st::FormatError("dagmh dictionary: <field> at byte <offset>: <what>").
class Dictionary {
 public:
  static std::shared_ptr<const Dictionary> open(std::vector<uint8_t> bytes);

  std::span<const uint8_t> bytes() const { return bytes_; }
  uint32_t crc() const { return crc_; }
  uint32_t node_words() const { return node_words_; }
  uint32_t treelet_count() const { return treelet_count_; }
  const uint8_t* nodes() const { return bytes_.data() + sizeof(DictHeader); }
  const uint8_t* treelets() const { return nodes() + size_t(node_words_) * 4; }
  // Values in the subtree of the node starting at word w; 0 if w is no node start.
  uint32_t node_values(uint32_t w) const { return w < values_.size() ? values_[w] : 0; }
  uint32_t treelet_values(uint32_t t) const;
  // Bytes held in memory (the buffer and the value counts), for a cache's budget.
  uint64_t memory_bytes() const { return bytes_.size() + values_.size() * 4; }

 private:
  std::vector<uint8_t> bytes_;
  std::vector<uint32_t> values_;
  uint32_t crc_ = 0, node_words_ = 0, treelet_count_ = 0;
};

}  // namespace st::dagmh

namespace st {
// open_dagmh (encoding.hpp) for a tile that may reference a pack dictionary: validated
// against `dict` (null: tiles without the dictionary flag only); the evaluator keeps `dict` alive.
std::unique_ptr<Evaluator> open_dagmh(std::span<const uint8_t> bytes, std::shared_ptr<const dagmh::Dictionary> dict);
}  // namespace st
