// The pack-wide DAG-MH dictionary (tiles/PACK.md "DAG-MH dictionary"; the dictionary's
// own format is tiles/core/DAGMH.md "Dictionary"). A DAG-MH pack with the feature
// dagmh_dictionary ends its grid section with one dictionary section, after the map
// preview, so the server's MapInfo delivers it once next to the skip grid:
//
//   off        size   field
//   0          4      magic "STDD" (0x44445453)
//   4          4      D: the dictionary's raw bytes, in [32, kMaxPackDictionaryBytes]
//   8          4      S: the stored bytes that follow, S <= max_stored_size(D)
//   12         4      CRC-32 (zlib polynomial) of those S bytes
//   16         S      the dictionary buffer ("DGMD", validated by dagmh::Dictionary::open)
//                     as a zlib stream (RFC 1950), like a tile's payload
//
// The section ends the grid section exactly (grid_size and grid_crc cover it). Encoded
// tiles of such a pack may be DAG-MH version 2 (references into the dictionary) or 1;
// version 2 tiles name the CRC-32 of the D raw bytes (DAG-MH header dictionary_crc).
//
// Hostile input: split_grid_section checks the preview's extent from its own header, the
// section header, the sizes, the CRC; open_pack_dictionary inflates exactly D bytes and
// validates the whole buffer. Errors are st::FormatError naming `what` and the byte offset.
#pragma once
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "tiles/core/encoding.hpp"
#include "tiles/core/pack_format.hpp"

namespace st {

namespace dagmh {
class Dictionary;
}

// Format constants: kPackDictionary* in pack_format.hpp (the grid section's sizes need them).

// A complete non-stack pack's grid section cut into its parts; `dictionary` is the DGMD
// buffer's zlib stream of `dictionary_raw` bytes (empty when the pack has none). `at` is
// the section's offset in the pack (for error messages).
struct GridSectionParts {
  std::span<const uint8_t> skip_grid, preview, dictionary;
  uint32_t dictionary_raw = 0;
};
GridSectionParts split_grid_section(std::span<const uint8_t> section, uint32_t skip_level, bool has_dictionary,
                                    const std::string& what, uint64_t at = 0);

// The dictionary section (header + the zlib stream of `dictionary` at libdeflate level
// `compression_level`) that follows the preview.
std::vector<uint8_t> dictionary_section(std::span<const uint8_t> dictionary, int compression_level);

// Inflates parts.dictionary to exactly parts.dictionary_raw bytes and validates the DGMD
// buffer (dagmh::Dictionary::open); st::FormatError prefixed by `what`.
std::shared_ptr<const dagmh::Dictionary> open_pack_dictionary(const GridSectionParts& parts, const std::string& what);

// Opens an encoded tile of a pack: open_encoded(e, raw), or for DAG-MH with a dictionary
// open_dagmh(raw, dict) (version 1 and 2 tiles alike). The evaluator keeps `dict` alive.
std::unique_ptr<Evaluator> open_pack_tile(Encoding e, std::span<const uint8_t> raw,
                                          const std::shared_ptr<const dagmh::Dictionary>& dict);

// Counts for a summary: inner nodes (node starts), node words, treelets, bytes.
struct DictionaryCounts {
  uint64_t bytes = 0, nodes = 0, node_words = 0, treelets = 0;
  uint32_t crc = 0;
};
DictionaryCounts count_dictionary(const dagmh::Dictionary& dict);

}  // namespace st
