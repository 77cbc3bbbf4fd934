#include "tiles/core/pack_dictionary.hpp"

#include "common/bytes.hpp"
#include "common/error.hpp"
#include "tiles/core/dagmh_validate.hpp"
#include "tiles/core/map_preview.hpp"
#include "tiles/core/pack_format.hpp"
#include "tiles/core/plane_tile.hpp"
#include "tiles/core/tile_cut_grid.hpp"

namespace st {

GridSectionParts split_grid_section(std::span<const uint8_t> section, uint32_t skip_level, bool has_dictionary,
                                    const std::string& what, uint64_t at) {
  auto fail = [&](uint64_t off, const std::string& why) {
    throw FormatError(what + " at byte " + std::to_string(at + off) + ": " + why);
  };
  const uint64_t g = CutGrid::serialized_size(skip_level);
  if (section.size() < g + kPreviewHeaderBytes) fail(0, "grid section shorter than the skip grid and a map preview");
  GridSectionParts parts;
  parts.skip_grid = section.first(g);
  if (!has_dictionary) {
    parts.preview = section.subspan(g);
    return parts;
  }
  // The preview's extent from its own header (map_preview.hpp): 16 + 8 w c + r bytes;
  // MapPreview::parse checks the fields themselves.
  const uint8_t* p = section.data() + g;
  const uint32_t levels = load_le<uint32_t>(p + 4), cells = load_le<uint32_t>(p + 8), residuals = load_le<uint32_t>(p + 12);
  if (levels > kMaxPreviewLevels) fail(g + 4, "map preview levels " + std::to_string(levels) + " > " + std::to_string(kMaxPreviewLevels));
  const uint64_t preview = kPreviewHeaderBytes + 8ull * MapPreview::words(levels) * cells + uint64_t(residuals);
  const uint64_t rest = section.size() - g;
  if (preview > kMaxPreviewBytes || preview > rest || rest - preview <= kPackDictionaryHeaderBytes)
    fail(g, "the map preview (" + std::to_string(preview) + " bytes) leaves no room for the DAG-MH dictionary the "
            "header's feature dagmh_dictionary announces");
  parts.preview = section.subspan(g, preview);
  const uint64_t d = g + preview;
  const uint8_t* h = section.data() + d;
  if (load_le<uint32_t>(h) != kPackDictionaryMagic) fail(d, "DAG-MH dictionary section: bad magic (want \"STDD\")");
  const uint32_t raw = load_le<uint32_t>(h + 4), stored = load_le<uint32_t>(h + 8), crc = load_le<uint32_t>(h + 12);
  if (raw < kMinPackDictionaryBytes || raw > kMaxPackDictionaryBytes)
    fail(d + 4, "DAG-MH dictionary of " + std::to_string(raw) + " bytes outside [32, " +
                    std::to_string(kMaxPackDictionaryBytes) + "]");
  if (stored == 0 || stored > max_stored_size(raw))
    fail(d + 8, "DAG-MH dictionary stored in " + std::to_string(stored) + " bytes, more than a zlib stream of " +
                    std::to_string(raw) + " bytes takes");
  if (uint64_t(stored) != rest - preview - kPackDictionaryHeaderBytes)
    fail(d + 8, "DAG-MH dictionary size " + std::to_string(stored) + " disagrees with the grid section, which leaves " +
                    std::to_string(rest - preview - kPackDictionaryHeaderBytes) + " bytes for it");
  parts.dictionary = section.subspan(d + kPackDictionaryHeaderBytes, stored);
  parts.dictionary_raw = raw;
  const uint32_t actual = crc32_of(parts.dictionary);
  if (actual != crc)
    fail(d + 12, "DAG-MH dictionary CRC mismatch (stored " + hex32(crc) + ", data " + hex32(actual) + ")");
  return parts;
}

std::vector<uint8_t> dictionary_section(std::span<const uint8_t> dictionary, int compression_level) {
  const std::vector<uint8_t> stored = zlib_compress(dictionary, compression_level);
  std::vector<uint8_t> out(kPackDictionaryHeaderBytes + stored.size(), 0);
  store_le<uint32_t>(out.data(), kPackDictionaryMagic);
  store_le<uint32_t>(out.data() + 4, uint32_t(dictionary.size()));
  store_le<uint32_t>(out.data() + 8, uint32_t(stored.size()));
  store_le<uint32_t>(out.data() + 12, crc32_of(stored));
  std::copy(stored.begin(), stored.end(), out.begin() + kPackDictionaryHeaderBytes);
  return out;
}

std::shared_ptr<const dagmh::Dictionary> open_pack_dictionary(const GridSectionParts& parts, const std::string& what) {
  try {
    return dagmh::Dictionary::open(zlib_decompress(parts.dictionary, parts.dictionary_raw, "zlib stream"));
  } catch (const Error& e) {
    throw FormatError(what + ": " + e.what());
  }
}

std::unique_ptr<Evaluator> open_pack_tile(Encoding e, std::span<const uint8_t> raw,
                                          const std::shared_ptr<const dagmh::Dictionary>& dict) {
  if (e != Encoding::vsdag && is_plane_buffer(raw))  // plane tiles (tiles/core/PLANES.md)
    return open_plane_tile(raw, [e, dict](std::span<const uint8_t> inner) { return open_pack_tile(e, inner, dict); });
  if (e == Encoding::dagmh && dict && !is_mmh_buffer(raw)) return open_dagmh(raw, dict);
  return open_encoded(e, raw);
}

DictionaryCounts count_dictionary(const dagmh::Dictionary& dict) {
  DictionaryCounts c;
  c.bytes = dict.bytes().size();
  c.node_words = dict.node_words();
  c.treelets = dict.treelet_count();
  c.crc = dict.crc();
  for (uint32_t w = 0; w < dict.node_words(); ++c.nodes)  // Dictionary::open checked every extent
    w += dagmh::node_words(load_le<uint32_t>(dict.nodes() + 4 * size_t(w)));
  return c;
}

}  // namespace st
