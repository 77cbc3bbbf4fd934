#include "tiles/core/pack_format.hpp"

#include "tiles/core/map_preview.hpp"

#include <libdeflate.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <memory>

#include "common/error.hpp"
#include "tiles/core/interval.hpp"
#include "tiles/core/light.hpp"
#include "tiles/core/stack_grid.hpp"
#include "common/bytes.hpp"

namespace st {


std::string tile_bytes_bounds() {
  char buf[48];  // (snprintf: g++ 12 warns falsely on short string concatenations here)
  std::snprintf(buf, sizeof buf, "[%u B, %u MiB]", kMinTileBytes, kMaxTileBytes >> 20);
  return buf;
}

std::pair<uint64_t, uint64_t> grid_section_bounds(uint32_t skip_level, bool dict) {
  const uint64_t grid = CutGrid::serialized_size(skip_level);
  return {grid + kPreviewHeaderBytes + (dict ? kPackDictionaryHeaderBytes + 1 : 0),
          grid + kMaxPreviewBytes + (dict ? kPackDictionaryHeaderBytes + max_stored_size(kMaxPackDictionaryBytes) : 0)};
}

std::vector<uint8_t> compress_grid_section(std::span<const uint8_t> raw, int level) {
  if (raw.size() > 0xFFFFFFFFull) throw Error("grid section of " + std::to_string(raw.size()) + " bytes exceeds 4 GiB");
  const std::vector<uint8_t> z = zlib_compress(raw, level);
  std::vector<uint8_t> out(kCompressedGridHeaderBytes + z.size());
  store_le<uint32_t>(out.data(), kCompressedGridMagic);
  store_le<uint32_t>(out.data() + 4, uint32_t(raw.size()));
  std::copy(z.begin(), z.end(), out.begin() + kCompressedGridHeaderBytes);
  return out;
}

std::vector<uint8_t> inflate_grid_section(std::span<const uint8_t> stored, uint64_t least, uint64_t most,
                                          const std::string& what) {
  if (stored.size() < kCompressedGridHeaderBytes + 1)
    throw FormatError(what + ": compressed grid section of " + std::to_string(stored.size()) + " bytes is too short");
  if (load_le<uint32_t>(stored.data()) != kCompressedGridMagic)
    throw FormatError(what + ": compressed grid section: bad magic " + hex32(load_le<uint32_t>(stored.data())));
  const uint32_t raw = load_le<uint32_t>(stored.data() + 4);
  if (raw < least || raw > most)
    throw FormatError(what + ": compressed grid section: inflated size " + std::to_string(raw) + " outside [" +
                      std::to_string(least) + ", " + std::to_string(most) + "]");
  if (stored.size() - kCompressedGridHeaderBytes > max_stored_size(raw))
    throw FormatError(what + ": compressed grid section: " + std::to_string(stored.size()) + " stored bytes for " +
                      std::to_string(raw) + " inflated");
  return zlib_decompress(stored.subspan(kCompressedGridHeaderBytes), raw, what + ": compressed grid section");
}

std::string hex32(uint32_t v) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "0x%08x", v);
  return buf;
}

uint32_t crc32_of(std::span<const uint8_t> bytes) {
  return libdeflate_crc32(0, bytes.data(), bytes.size());
}

// ---- header -------------------------------------------------------------------------

std::array<uint8_t, kPackHeaderBytes> PackHeader::serialize() const {
  std::array<uint8_t, kPackHeaderBytes> b{};
  uint8_t* p = b.data();
  std::memcpy(p, kPackMagic.data(), 8);
  store_le<uint32_t>(p + 8, kPackVersion);
  store_le<uint32_t>(p + 12, kPackHeaderBytes);
  store_le<uint32_t>(p + 16, uint32_t(state));
  store_le<uint32_t>(p + 20, flags);
  p[24] = uint8_t(encoding);
  p[25] = uint8_t(light_kind);
  p[26] = uint8_t(map_level);
  p[27] = uint8_t(skip_level);
  store_le<uint32_t>(p + 28, tile_bytes);
  store_le<uint64_t>(p + 32, scene_hash);
  for (size_t i = 0; i < 18; ++i) store_le<double>(p + 40 + 8 * i, light[i]);
  store_le<uint64_t>(p + 184, params_offset);
  store_le<uint64_t>(p + 192, params_size);
  store_le<uint64_t>(p + 200, journal_offset);
  store_le<uint64_t>(p + 208, grid_offset);
  store_le<uint64_t>(p + 216, grid_size);
  store_le<uint64_t>(p + 224, index_offset);
  store_le<uint64_t>(p + 232, tile_count);
  store_le<uint32_t>(p + 240, params_crc);
  store_le<uint32_t>(p + 244, grid_crc);
  store_le<uint32_t>(p + 248, index_crc);
  store_le<uint32_t>(p + 252, crc32_of({p, 252}));
  return b;
}

PackHeader PackHeader::parse(std::span<const uint8_t> b, const std::string& what) {
  auto fail = [&](size_t off, const std::string& msg) -> void {
    throw FormatError(what + ": header: " + msg + " at byte " + std::to_string(off));
  };
  if (b.size() < kPackHeaderBytes)
    fail(b.size(), "truncated (" + std::to_string(b.size()) + " of " +
                       std::to_string(kPackHeaderBytes) + " header bytes)");
  if (!std::equal(kPackMagic.begin(), kPackMagic.end(), b.begin())) fail(0, "not a shadowtile pack (bad magic)");
  uint32_t version = load_le<uint32_t>(b, 8);
  if (version != kPackVersion)
    fail(8, "unsupported version " + std::to_string(version) + " (this build reads " + std::to_string(kPackVersion) +
                (version < kPackVersion ? "; version 1 packs carry no map preview: rebuild the pack)" : ")"));
  if (load_le<uint32_t>(b, 12) != kPackHeaderBytes) fail(12, "bad header size");
  uint32_t stored_crc = load_le<uint32_t>(b, 252), crc = crc32_of(b.first(252));
  if (stored_crc != crc) fail(252, "header CRC mismatch (stored " + hex32(stored_crc) + ", computed " + hex32(crc) + ")");
  PackHeader h;
  uint32_t state = load_le<uint32_t>(b, 16);
  if (state > uint32_t(PackState::complete)) fail(16, "bad state " + std::to_string(state));
  h.state = PackState(state);
  h.flags = load_le<uint32_t>(b, 20);
  if (h.flags & ~uint32_t(kKnownFeatures)) fail(20, "unknown feature flags " + hex32(h.flags));
  // deep_shadow (bit 3) is read: PackReader checks the deep directory and tiles.
  if (b[24] > uint8_t(kLastEncoding))
    fail(24, "unknown encoding " + std::to_string(b[24]) + " (this build reads 0-" + std::to_string(int(kLastEncoding)) +
                 ": mh, mmh, dagmh, vsdag; written by a newer shadowtile?)");
  h.encoding = Encoding(b[24]);
  if (!light_kind_known(b[25])) fail(25, "unknown light kind " + std::to_string(b[25]));
  h.light_kind = LightKind(b[25]);
  h.map_level = b[26];
  h.skip_level = b[27];
  if (h.map_level > kMaxLevel) fail(26, "map level " + std::to_string(h.map_level) + " > 20");
  const bool stack = h.flags & uint32_t(kFeatureStack);  // K is an octree level (StackGrid checks it)
  if ((h.light_kind == LightKind::sun_ground || h.light_kind == LightKind::spot_window) && !stack)
    fail(25, "light kind " + std::to_string(b[25]) + " (" + light_kind_name(h.light_kind) +
                 ", a light set's sample frame) on a pack without the stack feature");
  if ((h.flags & uint32_t(kFeatureStackSliceTiles)) && !stack) fail(20, "feature stack_slice_tiles without stack");
  if ((h.flags & uint32_t(kFeatureStackSplitCells)) && !stack) fail(20, "feature stack_split_cells without stack");
  if ((h.flags & uint32_t(kFeatureStackGroupedTiles)) && !(h.flags & uint32_t(kFeatureStackSliceTiles)))
    fail(20, "feature stack_grouped_tiles without stack_slice_tiles");
  if ((h.flags & uint32_t(kFeaturePackedPlaneTiles)) && !(h.flags & uint32_t(kFeaturePlaneTiles)))
    fail(20, "feature packed_plane_tiles without plane_tiles");
  if ((h.flags & uint32_t(kFeaturePredictedPlaneLabels)) && !(h.flags & uint32_t(kFeaturePackedPlaneTiles)))
    fail(20, "feature predicted_plane_labels without packed_plane_tiles");
  if ((h.flags & uint32_t(kFeatureWidePlaneBlocks)) && !(h.flags & uint32_t(kFeaturePlaneTiles)))
    fail(20, "feature wide_plane_blocks without plane_tiles");
  if ((h.flags & uint32_t(kFeatureMixedTiles)) && (stack || h.encoding != Encoding::dagmh))
    fail(20, "feature mixed_tiles on a pack that is not a DAG-MH map (encoding " + to_string(h.encoding) + ")");
  // A stack's plane tiles are per-slice cells' slices (stack_slices.hpp).
  if ((h.flags & uint32_t(kFeaturePlaneTiles)) && (stack ? !(h.flags & uint32_t(kFeatureStackSliceTiles)) : h.encoding == Encoding::vsdag))
    fail(20, stack ? std::string("feature plane_tiles on a stack without stack_slice_tiles")
                   : "feature plane_tiles on a pack that is not an MH, MMH or DAG-MH map (encoding " + to_string(h.encoding) + ")");
  if ((h.flags & uint32_t(kFeatureDagmhDictionary)) && (stack || h.encoding != Encoding::dagmh))
    fail(20, "feature dagmh_dictionary on a pack whose tiles are not DAG-MH (encoding " + to_string(h.encoding) +
                 (stack ? ", a stack" : "") + ")");
  if (stack ? h.skip_level > kMaxLevel + 12 : h.skip_level > std::min(h.map_level, kMaxSkipLevel)) fail(27, "bad skip level " + std::to_string(h.skip_level));
  h.tile_bytes = load_le<uint32_t>(b, 28);
  if (h.tile_bytes == 0 || h.tile_bytes > kMaxTileBytes) fail(28, "bad tile_bytes " + std::to_string(h.tile_bytes));
  h.scene_hash = load_le<uint64_t>(b, 32);
  for (size_t i = 0; i < 18; ++i) h.light[i] = load_le<double>(b, 40 + 8 * i);
  h.params_offset = load_le<uint64_t>(b, 184);
  h.params_size = load_le<uint64_t>(b, 192);
  h.journal_offset = load_le<uint64_t>(b, 200);
  h.grid_offset = load_le<uint64_t>(b, 208);
  h.grid_size = load_le<uint64_t>(b, 216);
  h.index_offset = load_le<uint64_t>(b, 224);
  h.tile_count = load_le<uint64_t>(b, 232);
  h.params_crc = load_le<uint32_t>(b, 240);
  h.grid_crc = load_le<uint32_t>(b, 244);
  h.index_crc = load_le<uint32_t>(b, 248);
  // Section order: header, params, journal, grid, index (no overflow: each bound first).
  if (h.params_offset != kPackHeaderBytes) fail(184, "bad params offset");
  if (h.params_size > kMaxParamsBytes) fail(192, "params size " + std::to_string(h.params_size) + " too large");
  if (h.journal_offset != h.params_offset + h.params_size) fail(200, "bad journal offset");
  if (h.state == PackState::complete) {
    const uint64_t limit = uint64_t(1) << 56;
    if (h.grid_offset < h.journal_offset || h.grid_offset > limit || h.grid_offset % 8) fail(208, "bad grid offset");
    if (stack) {
      // A stack grid (stack_grid.hpp), stored as one zlib stream with compressed_grid.
      if (h.flags & uint32_t(kFeatureCompressedGrid)) {
        if (h.grid_size < kCompressedGridHeaderBytes + 1 || h.grid_size > kCompressedGridHeaderBytes + max_stored_size(kStackMaxGridBytes))
          fail(216, "compressed stack grid size " + std::to_string(h.grid_size) + " out of bounds");
      } else if (h.grid_size > kStackMaxGridBytes) {
        fail(216, "stack grid size too large");
      }
    } else {
      // The skip grid, then the map preview (map_preview.hpp): at least its header, at most its bound.
      // With the DAG-MH dictionary (pack_dictionary.hpp) its section follows the preview.
      const bool dict = h.flags & uint32_t(kFeatureDagmhDictionary);
      const auto [least, most] = grid_section_bounds(h.skip_level, dict);
      if (h.flags & uint32_t(kFeatureCompressedGrid)) {
        // Stored: the 8-byte header and a zlib stream of the section (inflated at open).
        if (h.grid_size < kCompressedGridHeaderBytes + 1 || h.grid_size > kCompressedGridHeaderBytes + max_stored_size(most))
          fail(216, "compressed grid section size " + std::to_string(h.grid_size) + " does not fit the skip level's grid (" +
                        std::to_string(CutGrid::serialized_size(h.skip_level)) + " bytes inflated)");
      } else if (h.grid_size < least || h.grid_size > most) {
        fail(216, "grid section size " + std::to_string(h.grid_size) + " does not fit the skip level's grid (" +
                      std::to_string(CutGrid::serialized_size(h.skip_level)) + " bytes) and a map preview" +
                      (dict ? " and a DAG-MH dictionary" : ""));
      }
    }
    if (h.index_offset != h.grid_offset + h.grid_size) fail(224, "bad index offset");
    if (h.tile_count > limit / kIndexEntryBytes) fail(232, "tile count too large");
    bool has_tiles = h.tile_count > 0;
    if (bool(h.flags & kFeatureHasTiles) != has_tiles) fail(20, "has_tiles flag disagrees with the tile count");
  }
  return h;
}

// ---- journal records ------------------------------------------------------------------

std::array<uint8_t, kRecordBytes> TileRecord::serialize() const {
  std::array<uint8_t, kRecordBytes> b{};
  store_le<uint32_t>(b.data(), kTileRecordMagic);
  b[4] = uint8_t(kind);
  store_le<uint64_t>(b.data() + 8, id);
  store_le<uint32_t>(b.data() + 16, stored_size);
  store_le<uint32_t>(b.data() + 20, raw_size);
  store_le<uint32_t>(b.data() + 24, crc);
  store_le<uint32_t>(b.data() + 28, crc32_of({b.data(), 28}));
  return b;
}

std::array<uint8_t, kRecordBytes> CellRecord::serialize() const {
  std::array<uint8_t, kRecordBytes> b{};
  store_le<uint32_t>(b.data(), kCellRecordMagic);
  b[4] = uint8_t(entry.kind);
  b[5] = entry.index_levels;
  store_le<uint32_t>(b.data() + 8, cx);
  store_le<uint32_t>(b.data() + 12, cy);
  store_le<float>(b.data() + 16, entry.value);
  store_le<float>(b.data() + 20, lo);
  store_le<float>(b.data() + 24, hi);
  store_le<uint32_t>(b.data() + 28, crc32_of({b.data(), 28}));
  return b;
}

RecordType parse_record(std::span<const uint8_t, kRecordBytes> b, TileRecord* tile, CellRecord* cell) {
  if (load_le<uint32_t>(b, 28) != crc32_of(b.first(28))) return RecordType::none;
  uint32_t magic = load_le<uint32_t>(b, 0);
  if (magic == kTileRecordMagic) {
    if (b[5] || b[6] || b[7]) return RecordType::none;
    if (b[4] < uint8_t(TileKind::encoded) || b[4] > uint8_t(TileKind::deep_directory)) return RecordType::none;
    tile->kind = TileKind(b[4]);
    tile->id = load_le<uint64_t>(b, 8);
    tile->stored_size = load_le<uint32_t>(b, 16);
    tile->raw_size = load_le<uint32_t>(b, 20);
    tile->crc = load_le<uint32_t>(b, 24);
    if (!id_fits_kind(tile->id, tile->kind) || tile->raw_size == 0 || tile->raw_size > kMaxTileBytes ||
        tile->stored_size == 0 || tile->stored_size > max_stored_size(tile->raw_size))
      return RecordType::none;
    return RecordType::tile;
  }
  if (magic == kCellRecordMagic) {
    if (b[6] || b[7] || b[4] > uint8_t(EntryKind::index)) return RecordType::none;
    cell->entry.kind = EntryKind(b[4]);
    cell->entry.index_levels = b[5];
    cell->cx = load_le<uint32_t>(b, 8);
    cell->cy = load_le<uint32_t>(b, 12);
    cell->entry.value = load_le<float>(b, 16);
    cell->lo = load_le<float>(b, 20);
    cell->hi = load_le<float>(b, 24);
    return RecordType::cell;
  }
  return RecordType::none;
}

// ---- deep ids --------------------------------------------------------------------------

bool is_valid_deep_id(uint64_t id) {
  return id == kDeepDirectoryId || (is_deep_id(id) && is_valid_tile_id(id & ~kDeepTileIdBit));
}

bool id_fits_kind(uint64_t id, TileKind kind) {
  switch (kind) {
    case TileKind::encoded:
    case TileKind::index: return is_valid_tile_id(id);
    case TileKind::deep: return id != kDeepDirectoryId && is_valid_deep_id(id);
    case TileKind::deep_directory: return id == kDeepDirectoryId;
  }
  return false;
}

// ---- tile index -----------------------------------------------------------------------

std::vector<uint8_t> serialize_index(std::span<const TileIndexEntry> entries) {
  std::vector<uint8_t> out;
  out.reserve(entries.size() * kIndexEntryBytes);
  for (const TileIndexEntry& e : entries) {
    append_le<uint64_t>(out, e.id);
    append_le<uint64_t>(out, e.offset);
    append_le<uint32_t>(out, e.stored_size);
    append_le<uint32_t>(out, e.raw_size);
    append_le<uint32_t>(out, e.crc);
    append_le<uint8_t>(out, uint8_t(e.kind));
    append_le<uint8_t>(out, 0);
    append_le<uint16_t>(out, 0);
  }
  return out;
}

std::vector<TileIndexEntry> parse_index(std::span<const uint8_t> bytes, uint64_t base_offset,
                                        uint64_t journal_begin, uint64_t journal_end, uint32_t tile_bytes,
                                        const std::string& what, bool payloads_only) {
  if (bytes.size() % kIndexEntryBytes) throw FormatError(what + ": tile index size not a multiple of 32");
  std::vector<TileIndexEntry> out(bytes.size() / kIndexEntryBytes);
  uint64_t next = journal_begin;  // payloads_only: where entry i's payload must start
  for (size_t i = 0; i < out.size(); ++i) {
    size_t o = i * kIndexEntryBytes;
    auto fail = [&](size_t field, const std::string& msg) {
      throw FormatError(what + ": tile index entry " + std::to_string(i) + ": " + msg + " at byte " +
                        std::to_string(base_offset + o + field));
    };
    TileIndexEntry& e = out[i];
    e.id = load_le<uint64_t>(bytes, o);
    e.offset = load_le<uint64_t>(bytes, o + 8);
    e.stored_size = load_le<uint32_t>(bytes, o + 16);
    e.raw_size = load_le<uint32_t>(bytes, o + 20);
    e.crc = load_le<uint32_t>(bytes, o + 24);
    uint8_t kind = bytes[o + 28];
    if (!is_valid_tile_id(e.id) && !is_valid_deep_id(e.id)) fail(0, "invalid " + describe_tile(e.id));
    if (i > 0 && e.id <= out[i - 1].id) fail(0, "ids not strictly increasing");
    if (kind < uint8_t(TileKind::encoded) || kind > uint8_t(TileKind::deep_directory)) fail(28, "bad tile kind");
    e.kind = TileKind(kind);
    if (!id_fits_kind(e.id, e.kind)) fail(28, "tile kind " + std::to_string(kind) + " does not fit " + describe_tile(e.id));
    if (bytes[o + 29] || load_le<uint16_t>(bytes, o + 30)) fail(29, "nonzero padding");
    if (e.raw_size == 0 || e.raw_size > tile_bytes || e.stored_size == 0 || e.stored_size > max_stored_size(e.raw_size))
      fail(16, describe_tile(e.id) + ": bad sizes (raw " + std::to_string(e.raw_size) + ", stored " +
                   std::to_string(e.stored_size) + ", tile_bytes " + std::to_string(tile_bytes) + ")");
    if (e.offset < journal_begin + (payloads_only ? 0 : kRecordBytes) || e.offset > journal_end ||
        journal_end - e.offset < e.stored_size)
      fail(8, describe_tile(e.id) + " payload [" + std::to_string(e.offset) + ", +" +
                  std::to_string(e.stored_size) + ") outside the journal");
    if (payloads_only) {
      if (e.offset != next)
        fail(8, describe_tile(e.id) + " payload at " + std::to_string(e.offset) + ", not right after the previous one (" +
                    std::to_string(next) + "): a payloads-only pack stores them back to back in index order");
      next = e.offset + e.stored_size;
    }
  }
  if (payloads_only && journal_end - next >= 8)
    throw FormatError(what + ": the tile payloads end at byte " + std::to_string(next) + ", " +
                      std::to_string(journal_end - next) + " bytes before the grid section (a payloads-only pack pads < 8)");
  return out;
}

std::vector<uint8_t> serialize_compact_index(std::span<const TileIndexEntry> entries, int level) {
  const size_t n = entries.size();
  std::vector<uint8_t> cols(n * kCompactIndexEntryBytes);
  uint8_t* p = cols.data();
  uint64_t prev = 0;
  for (size_t i = 0; i < n; ++i) store_le<uint64_t>(p + 8 * i, entries[i].id - prev), prev = entries[i].id;
  p += 8 * n;
  for (size_t i = 0; i < n; ++i) store_le<uint32_t>(p + 4 * i, entries[i].stored_size);
  p += 4 * n;
  for (size_t i = 0; i < n; ++i) store_le<uint32_t>(p + 4 * i, entries[i].raw_size);
  p += 4 * n;
  for (size_t i = 0; i < n; ++i) store_le<uint32_t>(p + 4 * i, entries[i].crc);
  p += 4 * n;
  for (size_t i = 0; i < n; ++i) p[i] = uint8_t(entries[i].kind);
  const std::vector<uint8_t> z = zlib_compress(cols, level);
  if (z.size() > 0xFFFFFFFFull) throw Error("tile index of " + std::to_string(n) + " entries exceeds 4 GiB stored");
  std::vector<uint8_t> out(kCompactIndexHeaderBytes + z.size());
  store_le<uint32_t>(out.data(), kCompactIndexMagic);
  store_le<uint32_t>(out.data() + 4, uint32_t(z.size()));
  std::copy(z.begin(), z.end(), out.begin() + kCompactIndexHeaderBytes);
  return out;
}

std::vector<TileIndexEntry> parse_compact_index(std::span<const uint8_t> section, uint64_t tile_count,
                                                uint64_t base_offset, uint64_t journal_begin, uint64_t journal_end,
                                                uint32_t tile_bytes, const std::string& what) {
  const std::string at = what + ": compact tile index at byte " + std::to_string(base_offset);
  if (section.size() < kCompactIndexHeaderBytes)
    throw FormatError(at + ": " + std::to_string(section.size()) + " bytes, too short for its header");
  if (load_le<uint32_t>(section.data()) != kCompactIndexMagic)
    throw FormatError(at + ": bad magic " + hex32(load_le<uint32_t>(section.data())));
  const uint64_t stored = load_le<uint32_t>(section.data() + 4);
  if (stored != section.size() - kCompactIndexHeaderBytes)
    throw FormatError(at + ": stream size " + std::to_string(stored) + " (byte " + std::to_string(base_offset + 4) +
                      ") but the section holds " + std::to_string(section.size() - kCompactIndexHeaderBytes) +
                      " bytes to the end of the file");
  if (tile_count > 0xFFFFFFFFull / kCompactIndexEntryBytes || stored == 0 ||
      stored > max_stored_size(tile_count * kCompactIndexEntryBytes))
    throw FormatError(at + ": " + std::to_string(stored) + " stored bytes do not fit " + std::to_string(tile_count) +
                      " tiles");
  const uint64_t n = tile_count;
  const std::vector<uint8_t> cols =
      zlib_decompress(section.subspan(kCompactIndexHeaderBytes), uint32_t(n * kCompactIndexEntryBytes), at);
  // The entries as serialize_index lays them out, offsets implied; parse_index checks them.
  std::vector<TileIndexEntry> entries(n);
  const uint8_t* p = cols.data();
  uint64_t id = 0, offset = journal_begin;
  for (uint64_t i = 0; i < n; ++i) {
    TileIndexEntry& e = entries[i];
    e.id = id += load_le<uint64_t>(p + 8 * i);
    e.stored_size = load_le<uint32_t>(p + 8 * n + 4 * i);
    e.raw_size = load_le<uint32_t>(p + 12 * n + 4 * i);
    e.crc = load_le<uint32_t>(p + 16 * n + 4 * i);
    e.offset = offset;
    offset += e.stored_size;
  }
  std::vector<uint8_t> plain = serialize_index(entries);
  for (uint64_t i = 0; i < n; ++i) plain[i * kIndexEntryBytes + 28] = p[20 * n + i];  // kinds as stored
  return parse_index(plain, base_offset, journal_begin, journal_end, tile_bytes, at, true);
}

// ---- params ---------------------------------------------------------------------------

namespace {
bool valid_key(const std::string& k) {
  if (k.empty()) return false;
  return std::all_of(k.begin(), k.end(), [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_' || c == '.' || c == '-';
  });
}
}  // namespace

std::vector<uint8_t> serialize_params(const PackParamList& params) {
  PackParamList sorted = params;
  std::sort(sorted.begin(), sorted.end());
  std::string text;
  for (size_t i = 0; i < sorted.size(); ++i) {
    auto& [k, v] = sorted[i];
    if (!valid_key(k)) throw Error("pack build parameter: bad key '" + k + "'");
    if (i > 0 && sorted[i - 1].first == k) throw Error("pack build parameter: duplicate key '" + k + "'");
    if (v.find('\n') != std::string::npos || v.find('\0') != std::string::npos)
      throw Error("pack build parameter '" + k + "': value has a newline or NUL");
    text += k + "=" + v + "\n";
  }
  if (text.size() > kMaxParamsBytes) throw Error("pack build parameters exceed 1 MiB");
  return std::vector<uint8_t>(text.begin(), text.end());
}

PackParamList parse_params(std::span<const uint8_t> bytes, const std::string& what) {
  PackParamList out;
  size_t pos = 0;
  while (pos < bytes.size()) {
    auto nl = std::find(bytes.begin() + pos, bytes.end(), uint8_t('\n'));
    if (nl == bytes.end()) throw FormatError(what + ": params: unterminated line at byte " + std::to_string(pos));
    std::string line(bytes.begin() + pos, nl);
    size_t eq = line.find('=');
    if (eq == std::string::npos || !valid_key(line.substr(0, eq)) || line.find('\0') != std::string::npos)
      throw FormatError(what + ": params: malformed line at byte " + std::to_string(pos));
    out.emplace_back(line.substr(0, eq), line.substr(eq + 1));
    pos = size_t(nl - bytes.begin()) + 1;
  }
  return out;
}

// ---- zlib via libdeflate --------------------------------------------------------------

std::vector<uint8_t> zlib_compress(std::span<const uint8_t> raw, int level) {
  struct Free {
    void operator()(libdeflate_compressor* c) const { libdeflate_free_compressor(c); }
  };
  // One compressor per thread and level (libdeflate's levels 0..12), kept like the
  // decompressor below: a compressor is 0.3-1 MB, and a stack build compresses thousands
  // of small cells, each of which allocated and freed one (under ASan a map and an unmap
  // each). A compressor keeps no state between calls: the bytes are the same.
  thread_local std::unique_ptr<libdeflate_compressor, Free> by_level[13];
  libdeflate_compressor* c = nullptr;
  if (level >= 0 && level <= 12) {
    if (!by_level[level]) by_level[level].reset(libdeflate_alloc_compressor(level));
    c = by_level[level].get();
  }
  if (!c) throw Error("zlib: cannot allocate a compressor at level " + std::to_string(level));
  std::vector<uint8_t> out(libdeflate_zlib_compress_bound(c, raw.size()));
  size_t n = libdeflate_zlib_compress(c, raw.data(), raw.size(), out.data(), out.size());
  ST_CHECK(n != 0 && n <= max_stored_size(raw.size()));  // libdeflate's bound guarantees both
  out.resize(n);
  return out;
}

void zlib_decompress_into(std::span<const uint8_t> stored, std::span<uint8_t> out, const std::string& what) {
  struct Free {
    void operator()(libdeflate_decompressor* d) const { libdeflate_free_decompressor(d); }
  };
  thread_local std::unique_ptr<libdeflate_decompressor, Free> d(libdeflate_alloc_decompressor());
  if (!d) throw Error("zlib: cannot allocate a decompressor");
  const size_t raw_size = out.size();
  size_t in_used = 0, out_used = 0;
  libdeflate_result r = libdeflate_zlib_decompress_ex(d.get(), stored.data(), stored.size(), out.data(),
                                                      out.size(), &in_used, &out_used);
  if (r == LIBDEFLATE_INSUFFICIENT_SPACE)
    throw FormatError(what + ": decompresses to more than the recorded " + std::to_string(raw_size) + " bytes");
  if (r != LIBDEFLATE_SUCCESS) throw FormatError(what + ": malformed zlib stream");
  if (out_used != raw_size)
    throw FormatError(what + ": decompresses to " + std::to_string(out_used) + " bytes, recorded " +
                      std::to_string(raw_size));
  if (in_used != stored.size()) throw FormatError(what + ": trailing bytes after the zlib stream");
}

std::vector<uint8_t> zlib_decompress(std::span<const uint8_t> stored, uint32_t raw_size,
                                     const std::string& what) {
  std::vector<uint8_t> out(raw_size);
  zlib_decompress_into(stored, out, what);
  return out;
}

}  // namespace st
