// Reads a pack file (pack_format.hpp, tiles/PACK.md). Hostile input is the normal case:
// open() checks the header, the section layout against the file size, the CRCs of the
// params, skip grid and tile index, every index entry and that every skip-grid entry that
// names a tile finds it, and refuses a light no build makes (tiles/PACK.md "Reading
// hostile packs"); read_stored() checks a tile's CRC on every read; verify() checks every
// byte of the file and the coarse levels against the cell intervals. Every failure is an st::FormatError naming the pack, and the
// tile id and byte offset where there is one.
//
// Thread safety: all const methods may be called concurrently (reads use pread).
// The skip grid, params and tile index are held in memory (the tile payloads are not).
#pragma once
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "tiles/core/deep_directory.hpp"
#include "tiles/core/evaluator.hpp"
#include "tiles/core/pack_format.hpp"
#include "tiles/core/tile_cut_grid.hpp"

namespace st {

class MapPreview;
struct StackGrid;
namespace dagmh {
class Dictionary;
}

class PackReader {
 public:
  static std::unique_ptr<PackReader> open(const std::string& path);
  // A pack held in memory (tests; a server that keeps small packs resident).
  static std::unique_ptr<PackReader> open_memory(std::vector<uint8_t> bytes, const std::string& name);
  ~PackReader();
  PackReader(const PackReader&) = delete;
  PackReader& operator=(const PackReader&) = delete;

  const std::string& name() const { return name_; }
  const PackHeader& header() const { return header_; }
  uint32_t map_level() const { return header_.map_level; }
  uint32_t skip_level() const { return header_.skip_level; }
  Encoding encoding() const { return header_.encoding; }
  LightSpace light() const { return LightSpace::from_array(header_.light_kind, header_.light); }
  const PackParamList& params() const { return params_; }
  const CutGrid& grid() const { return grid_; }
  // The map preview that follows the skip grid (map_preview.hpp).
  const MapPreview& preview() const { return *preview_; }
  // The pack-wide DAG-MH dictionary (feature dagmh_dictionary; pack_dictionary.hpp),
  // validated at open, else null. Encoded tiles open with it: open_tile().
  const std::shared_ptr<const dagmh::Dictionary>& dictionary() const { return dictionary_; }
  // Opens an encoded tile's raw bytes in this pack's encoding (with its dictionary):
  // what every reader of tiles calls. open_encoded alone refuses version-2 DAG-MH tiles.
  std::unique_ptr<Evaluator> open_tile(std::span<const uint8_t> raw) const;
  // A stack pack's grid (kFeatureStack; tiles/PACK.md "Stack packs"), else nullptr; then
  // grid() is empty and every tile is an MH octree buffer (mh_octree.hpp).
  const StackGrid* stack() const { return stack_.get(); }
  uint64_t file_size() const { return file_size_; }

  // Raw blobs a server sends as they lie (grid_bytes: the skip grid, the map preview and
  // the DAG-MH dictionary if any).
  std::span<const uint8_t> header_bytes() const { return header_bytes_; }
  std::span<const uint8_t> grid_bytes() const { return grid_bytes_; }

  const std::vector<TileIndexEntry>& tiles() const { return index_; }
  // The deep directory (deep_pack.hpp) of a pack with the deep_shadow feature, checked
  // against the index at open (its deep tiles are exactly the bitmap's); else null.
  const DeepDirectory* deep_directory() const { return deep_ ? &*deep_ : nullptr; }
  std::optional<TileIndexEntry> find(uint64_t id) const;
  // The tile's stored (zlib) bytes, CRC checked; throws st::FormatError if the id is
  // unknown or the bytes are corrupt.
  std::vector<uint8_t> read_stored(uint64_t id) const;
  // Stored bytes, decompressed; the size checked against the index.
  std::vector<uint8_t> read_raw(uint64_t id) const;
  // read_raw into the first bytes of `out` (a cache slot); returns the raw size. Throws
  // st::FormatError if the tile's raw size exceeds out.size().
  size_t read_raw_into(uint64_t id, std::span<uint8_t> out) const;
  // An index tile, parsed and checked against the entry that points at it.
  CutGrid read_index_tile(uint64_t id, const GridEntry& parent) const;

  // Checks the whole file: every journal record, every tile's CRC, size and zlib stream,
  // every index tile, that the page table reaches every tile exactly once, that every
  // cell record agrees with the skip grid and, with `open_tile`, that every encoded tile
  // opens (the encoding validates its whole buffer) with the right finest level; every
  // deep tile opens (DeepTileView validates it) with the directory's side.
  using TileOpener = std::function<std::unique_ptr<Evaluator>(std::span<const uint8_t>)>;
  void verify(const TileOpener& open_tile = {}) const;
  // open_tile() as a TileOpener (it holds the dictionary, not this reader).
  TileOpener tile_opener() const;
  // Throws st::FormatError unless every skip-grid value (coarse and entry) lies in the
  // depth range [0, 1] that every bake writes (light-space depth, kLitDepth = 1). The
  // format itself carries any non-NaN float (tests encode such fields), so open() and
  // verify() do not ask this; the CLI's verify and export do.
  void check_depth_range() const;

  std::string where(uint64_t offset) const;  // "<name> at byte N"
  // Multi-line human-readable summary (header fields, features, tile counts and sizes),
  // for `shadowtile info` and logs.
  std::string summary() const;

 private:
  struct Source;
  PackReader(std::unique_ptr<Source> src, std::string name);
  void load();
  void load_deep();  // the deep directory against the index (deep_shadow feature)
  void read_at(uint64_t offset, std::span<uint8_t> out) const;
  // CRC-32 of [offset, offset + size), read kChunkBytes at a time.
  uint32_t crc32_of_range(uint64_t offset, uint64_t size) const;
  // verify(): the coarse levels and cell records against each other and the depth range.
  void check_coarse_levels(const std::vector<CellRecord>& cells) const;
  // verify() past the journal: page table, tiles, deep tiles, map preview.
  void verify_tiles(const TileOpener& open_tile) const;
  // load() / verify() of a stack pack (pack_reader_stack.cpp).
  void load_stack();
  void check_stack_index() const;
  void verify_stack() const;
  void check_stack_range() const;
  std::string stack_summary() const;
  static constexpr uint64_t kChunkBytes = uint64_t(1) << 20;

  std::unique_ptr<Source> src_;
  std::string name_;
  PackHeader header_;
  uint64_t file_size_ = 0;  // the whole file (a payloads-only pack ends with its compact index)
  std::vector<uint8_t> header_bytes_, grid_bytes_;
  PackParamList params_;
  CutGrid grid_;
  std::shared_ptr<const MapPreview> preview_;
  std::shared_ptr<const dagmh::Dictionary> dictionary_;
  std::unique_ptr<StackGrid> stack_;
  std::vector<TileIndexEntry> index_;
  std::optional<DeepDirectory> deep_;
};

}  // namespace st
