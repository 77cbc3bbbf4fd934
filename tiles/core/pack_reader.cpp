#include "tiles/core/pack_reader.hpp"

#include "tiles/core/stack_slices.hpp"
#include "tiles/core/plane_pack.hpp"
#include "tiles/core/pack_light_check.hpp"
#include "tiles/core/coarse_hulls.hpp"

#include "tiles/core/map_preview.hpp"
#include "tiles/core/pack_dictionary.hpp"
#include "tiles/core/dagmh_validate.hpp"
#include "tiles/core/deep_tile.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <map>

#include <libdeflate.h>

#include "common/error.hpp"
#include "common/text.hpp"
#include "tiles/core/interval.hpp"
#include "tiles/core/page_table.hpp"
#include "tiles/core/stack_grid.hpp"

namespace st {

struct PackReader::Source {
  int fd = -1;
  std::vector<uint8_t> memory;
  uint64_t size = 0;
  ~Source() {
    if (fd >= 0) ::close(fd);
  }
};

PackReader::PackReader(std::unique_ptr<Source> src, std::string name) : src_(std::move(src)), name_(std::move(name)) {}
PackReader::~PackReader() = default;

std::unique_ptr<PackReader> PackReader::open(const std::string& path) {
  auto src = std::make_unique<Source>();
  src->fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (src->fd < 0) throw Error(path + ": cannot open: " + std::strerror(errno));
  struct stat st{};
  if (::fstat(src->fd, &st) != 0) throw Error(path + ": stat: " + std::strerror(errno));
  if (!S_ISREG(st.st_mode)) throw Error(path + ": not a regular file");
  src->size = uint64_t(st.st_size);
  std::unique_ptr<PackReader> r(new PackReader(std::move(src), path));
  r->load();
  return r;
}

std::unique_ptr<PackReader> PackReader::open_memory(std::vector<uint8_t> bytes, const std::string& name) {
  auto src = std::make_unique<Source>();
  src->size = bytes.size();
  src->memory = std::move(bytes);
  std::unique_ptr<PackReader> r(new PackReader(std::move(src), name));
  r->load();
  return r;
}

std::string PackReader::where(uint64_t offset) const { return name_ + " at byte " + std::to_string(offset); }

void PackReader::read_at(uint64_t offset, std::span<uint8_t> out) const {
  if (offset > src_->size || src_->size - offset < out.size())
    throw FormatError(name_ + ": truncated: need bytes [" + std::to_string(offset) + ", " +
                      std::to_string(offset + out.size()) + "), file has " + std::to_string(src_->size));
  // An empty section (no tiles: an empty tile index) reads nothing; memcpy from/to the
  // null data() of an empty vector is undefined even for 0 bytes (UBSan, pack_reader_fuzz).
  if (out.empty()) return;
  if (src_->fd < 0) {
    std::memcpy(out.data(), src_->memory.data() + offset, out.size());
    return;
  }
  size_t done = 0;
  while (done < out.size()) {
    ssize_t n = ::pread(src_->fd, out.data() + done, out.size() - done, off_t(offset + done));
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) throw Error(name_ + ": read at byte " + std::to_string(offset + done) + ": " + std::strerror(errno));
    if (n == 0) throw FormatError(name_ + ": truncated (file shrank) at byte " + std::to_string(offset + done));
    done += size_t(n);
  }
}

namespace {

// Every value of `g` inside the depth range [0, 1] (kLitDepth = 1 for a ray that hits
// nothing), as every bake writes.
void check_grid_range(const CutGrid& g, const std::string& what) {
  for (size_t i = 0; i < g.coarse.size(); ++i)
    if (!(g.coarse[i] >= 0.0f && g.coarse[i] <= kLitDepth))
      throw FormatError(what + ": coarse value " + std::to_string(i) + " is " + std::to_string(g.coarse[i]) +
                        ", outside the depth range [0, 1]");
  for (size_t i = 0; i < g.entries.size(); ++i)
    if (!(g.entries[i].value >= 0.0f && g.entries[i].value <= kLitDepth))
      throw FormatError(what + ": entry " + std::to_string(i) + " value is " + std::to_string(g.entries[i].value) +
                        ", outside the depth range [0, 1]");
}

}  // namespace

uint32_t PackReader::crc32_of_range(uint64_t offset, uint64_t size) const {
  std::vector<uint8_t> chunk(size_t(std::min<uint64_t>(size, kChunkBytes)));
  uint32_t crc = 0;
  for (uint64_t done = 0; done < size;) {
    const size_t n = size_t(std::min<uint64_t>(size - done, chunk.size()));
    read_at(offset + done, {chunk.data(), n});
    crc = libdeflate_crc32(crc, chunk.data(), n);
    done += n;
  }
  return crc;
}

void PackReader::load() {
  const uint64_t size = src_->size;
  if (size < kPackHeaderBytes)
    throw FormatError(name_ + ": truncated: " + std::to_string(size) + " bytes, the header alone needs " +
                      std::to_string(kPackHeaderBytes));
  header_bytes_.resize(kPackHeaderBytes);
  read_at(0, header_bytes_);
  header_ = PackHeader::parse(header_bytes_, name_);
  file_size_ = size;
  check_header_light(header_, name_);
  if (header_.state != PackState::complete)
    throw FormatError(name_ + ": an unfinished build (state 'building'): resume or rebuild it");
  // A payloads-only pack's compact index is the rest of the file (its header names its size).
  const bool payloads_only = header_.flags & kFeaturePayloadsOnly;
  if (header_.grid_offset > size || header_.index_offset > size ||
      (!payloads_only && (size - header_.index_offset) / kIndexEntryBytes < header_.tile_count))
    throw FormatError(name_ + ": truncated: the header needs " +
                      std::to_string(payloads_only ? header_.index_offset : header_.file_size()) +
                      " bytes, the file has " + std::to_string(size));
  if (payloads_only) {  // the compact index's header names where the file ends
    std::array<uint8_t, kCompactIndexHeaderBytes> head{};
    if (size - header_.index_offset < head.size())
      throw FormatError(name_ + ": truncated: the compact tile index at byte " + std::to_string(header_.index_offset) +
                        " needs its 8-byte header");
    read_at(header_.index_offset, head);
    const uint64_t end = header_.index_offset + head.size() + (uint64_t(head[4]) | uint64_t(head[5]) << 8 |
                                                                uint64_t(head[6]) << 16 | uint64_t(head[7]) << 24);
    if (size < end)
      throw FormatError(name_ + ": truncated: the compact tile index ends at byte " + std::to_string(end) +
                        ", the file has " + std::to_string(size));
    if (size > end)
      throw FormatError(name_ + ": " + std::to_string(size - end) + " trailing bytes after the compact tile index at byte " +
                        std::to_string(end));
  } else if (size != header_.file_size())
    throw FormatError(name_ + ": " + std::to_string(size - header_.file_size()) + " trailing bytes after the tile index at byte " +
                      std::to_string(header_.file_size()));

  std::vector<uint8_t> blob(header_.params_size);
  read_at(header_.params_offset, blob);
  if (crc32_of(blob) != header_.params_crc) throw FormatError(where(header_.params_offset) + ": build parameters CRC mismatch");
  params_ = parse_params(blob, name_);

  grid_bytes_.resize(header_.grid_size);
  read_at(header_.grid_offset, grid_bytes_);
  if (crc32_of(grid_bytes_) != header_.grid_crc) throw FormatError(where(header_.grid_offset) + ": skip grid CRC mismatch");
  if (header_.flags & kFeatureCompressedGrid) {  // tiles/PACK.md "Compressed grid section"
    const auto [least, most] = header_.flags & kFeatureStack
                                   ? std::pair<uint64_t, uint64_t>(kStackGridFixedBytes, kStackMaxGridBytes)
                                   : grid_section_bounds(header_.skip_level, header_.flags & kFeatureDagmhDictionary);
    grid_bytes_ = inflate_grid_section(grid_bytes_, least, most, where(header_.grid_offset));
  }
  if (header_.flags & kFeatureStack) {
    load_stack();
    preview_ = std::make_shared<MapPreview>();  // a stack pack's grid section is its stack grid
  } else {
    // The skip grid, the map preview, the DAG-MH dictionary if any (the header checked the
    // section's size).
    const size_t g = CutGrid::serialized_size(header_.skip_level);
    const bool has_dict = header_.flags & kFeatureDagmhDictionary;
    const GridSectionParts parts =
        split_grid_section(grid_bytes_, header_.skip_level, has_dict, name_ + ": grid section", header_.grid_offset);
    grid_ = CutGrid::parse(parts.skip_grid, name_ + ": skip grid at byte " + std::to_string(header_.grid_offset));
    if (grid_.levels != header_.skip_level)
      throw FormatError(where(header_.grid_offset) + ": skip grid levels != skip level");
    preview_ = std::make_shared<MapPreview>(MapPreview::parse(
        parts.preview, grid_, header_.map_level, name_ + " (byte " + std::to_string(header_.grid_offset + g) + ")"));
    if (has_dict)
      dictionary_ = open_pack_dictionary(
          parts, where(header_.grid_offset + uint64_t(parts.dictionary.data() - grid_bytes_.data())) +
                     ": DAG-MH dictionary");
  }

  // Every tile has a 32-byte record in the journal before the grid, so the index cannot
  // name more tiles than that room holds. A sparse file may still claim gigabytes: the
  // index CRC is checked in bounded chunks before the index is held in memory, so a
  // reader allocates what the file really holds, never its apparent size at once.
  // (Payloads only: every tile's zlib stream takes at least kMinStoredBytes.)
  if (header_.tile_count > (header_.grid_offset - header_.journal_offset) / (payloads_only ? kMinStoredBytes : kRecordBytes))
    throw FormatError(where(232) + ": header: " + std::to_string(header_.tile_count) + " tiles cannot fit a journal of " +
                      std::to_string(header_.grid_offset - header_.journal_offset) + " bytes");
  const uint64_t index_size = payloads_only ? size - header_.index_offset : header_.tile_count * kIndexEntryBytes;
  if (index_size > kChunkBytes && crc32_of_range(header_.index_offset, index_size) != header_.index_crc)
    throw FormatError(where(header_.index_offset) + ": tile index CRC mismatch");
  if (payloads_only && index_size > kCompactIndexHeaderBytes + max_stored_size(header_.tile_count * kCompactIndexEntryBytes))
    throw FormatError(where(header_.index_offset) + ": compact tile index of " + std::to_string(index_size) +
                      " bytes is larger than " + std::to_string(header_.tile_count) + " tiles can need");
  std::vector<uint8_t> index_bytes(index_size);
  read_at(header_.index_offset, index_bytes);
  if (crc32_of(index_bytes) != header_.index_crc) throw FormatError(where(header_.index_offset) + ": tile index CRC mismatch");
  index_ = payloads_only ? parse_compact_index(index_bytes, header_.tile_count, header_.index_offset,
                                               header_.journal_offset, header_.grid_offset, header_.tile_bytes, name_)
                        : parse_index(index_bytes, header_.index_offset, header_.journal_offset, header_.grid_offset,
                                      header_.tile_bytes, name_);
  if (stack_) return check_stack_index();

  load_deep();
  bool any_index = std::any_of(index_.begin(), index_.end(), [](auto& e) { return e.kind == TileKind::index; });
  if (any_index != bool(header_.flags & kFeatureIndexTiles))
    throw FormatError(where(20) + ": index_tiles flag disagrees with the tile index");
  const uint32_t k = header_.skip_level;
  for (uint32_t cy = 0; cy < (1u << k); ++cy)
    for (uint32_t cx = 0; cx < (1u << k); ++cx) {
      const GridEntry& e = grid_.entry(cx, cy);
      if (e.kind == EntryKind::constant) continue;
      uint64_t id = make_tile_id(k, cx, cy);
      auto t = find(id);
      if (!t || uint8_t(t->kind) != uint8_t(e.kind) || (k == header_.map_level))
        throw FormatError(name_ + ": skip grid entry (" + std::to_string(cx) + ", " + std::to_string(cy) + ") names " +
                          describe_tile(id) + ", which the tile index lacks or holds with another kind");
    }
}

void PackReader::load_deep() {
  // Deep ids sort after every opaque id (bit 63): the deep part is the index's tail.
  const auto first_deep = std::find_if(index_.begin(), index_.end(), [](auto& e) { return is_deep_id(e.id); });
  const bool flag = header_.flags & kFeatureDeepShadow;
  if (!flag) {
    if (first_deep != index_.end())
      throw FormatError(name_ + ": " + describe_tile(first_deep->id) + " in a pack without the deep_shadow feature");
    return;
  }
  if (index_.empty() || index_.back().id != kDeepDirectoryId)
    throw FormatError(where(20) + ": feature deep_shadow, but the tile index has no deep directory");
  deep_ = DeepDirectory::parse(read_raw(kDeepDirectoryId), name_ + ": " + describe_tile(kDeepDirectoryId));
  const uint64_t tiles = uint64_t(index_.end() - first_deep) - 1;
  if (tiles != deep_->tile_count())
    throw FormatError(name_ + ": the deep directory lists " + std::to_string(deep_->tile_count()) +
                      " deep tiles, the tile index holds " + std::to_string(tiles));
  for (auto it = first_deep; it + 1 != index_.end(); ++it) {
    const TileAddress a = tile_address(it->id & ~kDeepTileIdBit);
    if (a.level != deep_->tiles_per_side_bits() || !deep_->has(a.x, a.y))
      throw FormatError(name_ + ": " + describe_tile(it->id) + " is not in the deep directory");
  }
}

std::optional<TileIndexEntry> PackReader::find(uint64_t id) const {
  auto it = std::lower_bound(index_.begin(), index_.end(), id, [](const TileIndexEntry& e, uint64_t v) { return e.id < v; });
  if (it == index_.end() || it->id != id) return std::nullopt;
  return *it;
}

std::unique_ptr<Evaluator> PackReader::open_tile(std::span<const uint8_t> raw) const {
  return open_pack_tile(header_.encoding, raw, dictionary_);
}

PackReader::TileOpener PackReader::tile_opener() const {
  return [e = header_.encoding, d = dictionary_](std::span<const uint8_t> raw) { return open_pack_tile(e, raw, d); };
}

std::vector<uint8_t> PackReader::read_stored(uint64_t id) const {
  auto t = find(id);
  if (!t) throw FormatError(name_ + ": " + describe_tile(id) + " is not in the tile index");
  std::vector<uint8_t> stored(t->stored_size);
  read_at(t->offset, stored);
  uint32_t crc = crc32_of(stored);
  if (crc != t->crc)
    throw FormatError(name_ + ": " + describe_tile(id) + " at byte " + std::to_string(t->offset) +
                      ": CRC32 mismatch (index " + hex32(t->crc) + ", data " + hex32(crc) + ")");
  return stored;
}

namespace {

// One stored form back to its plain bytes in place, by `unpack`: refused by name when the
// pack's flags lack `feature`, the form's `bit_name`; the unpacker's error gains the tile's name.
void pack_reader_unpack(const PackHeader& h, uint32_t feature, const char* form, const char* bit_name,
                        std::span<uint8_t> raw, const std::string& what, const std::function<void(std::span<uint8_t>)>& unpack) {
  if (!(h.flags & feature))
    throw FormatError(what + ": " + form + " in a pack without feature " + bit_name);
  try {
    unpack(raw);
  } catch (const FormatError& e) {
    throw FormatError(what + ": " + e.what());
  }
}

// A stack pack's grouped per-slice cell ("STSP", stack_slices.hpp) back to its STSL bytes,
// and a packed plane tile ("STPQ" or "STPL", plane_pack.hpp) back to its STPN bytes, in place;
// anything else is left alone.
void pack_reader_ungroup(const PackHeader& h, bool stack, std::span<uint8_t> raw, const std::string& what) {
  if (!stack && (plane_tile_features(raw) & kFeatureWidePlaneBlocks) && !(h.flags & kFeatureWidePlaneBlocks))
    throw FormatError(what + ": a plane tile with wide labelled blocks (version 3) in a pack without feature wide_plane_blocks");
  if (!stack && is_packed_plane_tile(raw)) {
    if ((h.flags & kFeaturePackedPlaneTiles) && !(h.flags & kFeaturePredictedPlaneLabels) &&
        (packed_plane_tile_features(raw) & kFeaturePredictedPlaneLabels))
      throw FormatError(what + ": a plane tile with predicted labels (\"STPL\") in a pack without feature predicted_plane_labels");
    pack_reader_unpack(h, kFeaturePackedPlaneTiles, "a packed plane tile (\"STPQ\" or \"STPL\")", "packed_plane_tiles",
                       raw, what, unpack_plane_tile);
  } else if (stack && is_grouped_slice_tiles(raw)) {
    uint32_t need = 0;  // what its packed plane slices need
    pack_reader_unpack(h, kFeatureStackGroupedTiles, "a grouped per-slice cell (\"STSP\")", "stack_grouped_tiles", raw,
                       what, [&](std::span<uint8_t> r) { ungroup_slice_tiles(r, &need); });
    for (auto [bit, name] : {std::pair{kFeaturePlaneTiles, "plane_tiles"}, std::pair{kFeaturePackedPlaneTiles, "packed_plane_tiles"},
                             std::pair{kFeaturePredictedPlaneLabels, "predicted_plane_labels"},
                             std::pair{kFeatureWidePlaneBlocks, "wide_plane_blocks"}})
      if ((need & bit) && !(h.flags & bit))
        throw FormatError(what + ": a per-slice cell with packed plane slices in a pack without feature " + name);
  }
}

}  // namespace

std::vector<uint8_t> PackReader::read_raw(uint64_t id) const {
  std::vector<uint8_t> stored = read_stored(id);
  auto t = find(id);
  const std::string what = name_ + ": " + describe_tile(id) + " at byte " + std::to_string(t->offset);
  std::vector<uint8_t> raw = zlib_decompress(stored, t->raw_size, what);
  pack_reader_ungroup(header_, stack() != nullptr, raw, what);
  return raw;
}

size_t PackReader::read_raw_into(uint64_t id, std::span<uint8_t> out) const {
  std::vector<uint8_t> stored = read_stored(id);
  auto t = find(id);
  const std::string what = name_ + ": " + describe_tile(id) + " at byte " + std::to_string(t->offset);
  if (t->raw_size > out.size())
    throw FormatError(what + ": " + std::to_string(t->raw_size) + " raw bytes exceed the " +
                      std::to_string(out.size()) + "-byte slot");
  zlib_decompress_into(stored, out.first(t->raw_size), what);
  pack_reader_ungroup(header_, stack() != nullptr, out.first(t->raw_size), what);
  return t->raw_size;
}

CutGrid PackReader::read_index_tile(uint64_t id, const GridEntry& parent) const {
  auto t = find(id);
  const std::string what = name_ + ": index " + describe_tile(id) + " at byte " + std::to_string(t ? t->offset : 0);
  if (!t || t->kind != TileKind::index) throw FormatError(what + ": not an index tile in the tile index");
  CutGrid g = CutGrid::parse(read_raw(id), what, kMaxIndexLevels);
  TileAddress a = tile_address(id);
  if (g.levels != parent.index_levels || a.level + g.levels > header_.map_level)
    throw FormatError(what + ": has " + std::to_string(g.levels) + " levels, its entry says " +
                      std::to_string(parent.index_levels));
  if (std::memcmp(&g.coarse[0], &parent.value, sizeof(float)) != 0)
    throw FormatError(what + ": root value differs from its entry's");
  return g;
}

void PackReader::verify(const TileOpener& open_tile) const {
  if (header_.flags & kFeaturePayloadsOnly) {
    // 1. No journal records: the payloads fill the section back to back (parse_index
    // checked it), then < 8 zero bytes of padding. The cell records' intervals stayed in
    // the build's journal, so the coarse levels are not checked against them here
    // (`shadowtile verify PACK SCENE` re-traces the map instead).
    const uint64_t end = index_.empty() ? header_.journal_offset : index_.back().offset + index_.back().stored_size;
    std::vector<uint8_t> pad(header_.grid_offset - end);
    read_at(end, pad);
    if (std::any_of(pad.begin(), pad.end(), [](uint8_t b) { return b != 0; }))
      throw FormatError(where(end) + ": nonzero padding before the skip grid");
    for (const TileIndexEntry& e : index_) read_stored(e.id);  // every CRC
    if (stack_) return verify_stack();
    return verify_tiles(open_tile);
  }
  // 1. The journal: a clean sequence of records, then < 8 zero bytes of padding.
  std::map<uint64_t, TileRecord> records;  // payload offset -> record
  std::vector<CellRecord> cells;
  uint64_t pos = header_.journal_offset;
  const uint64_t end = header_.grid_offset;
  while (pos < end) {
    if (end - pos < 8) {
      std::vector<uint8_t> pad(end - pos);
      read_at(pos, pad);
      if (std::any_of(pad.begin(), pad.end(), [](uint8_t b) { return b != 0; }))
        throw FormatError(where(pos) + ": nonzero padding before the skip grid");
      break;
    }
    std::array<uint8_t, kRecordBytes> rec{};
    if (end - pos < kRecordBytes) throw FormatError(where(pos) + ": torn journal record");
    read_at(pos, rec);
    TileRecord t;
    CellRecord c;
    RecordType type = parse_record(rec, &t, &c);
    if (type == RecordType::none) throw FormatError(where(pos) + ": corrupt journal record (bad magic, field or CRC)");
    if (type == RecordType::cell) {
      cells.push_back(c);
      pos += kRecordBytes;
      continue;
    }
    if (end - pos - kRecordBytes < t.stored_size)
      throw FormatError(where(pos) + ": journal record of " + describe_tile(t.id) + " runs past the journal");
    records[pos + kRecordBytes] = t;
    pos += kRecordBytes + t.stored_size;
  }
  if (records.size() != index_.size())
    throw FormatError(name_ + ": journal holds " + std::to_string(records.size()) + " tiles, the index " +
                      std::to_string(index_.size()));
  for (const TileIndexEntry& e : index_) {
    auto it = records.find(e.offset);
    if (it == records.end() || it->second.id != e.id || it->second.kind != e.kind ||
        it->second.stored_size != e.stored_size || it->second.raw_size != e.raw_size || it->second.crc != e.crc)
      throw FormatError(name_ + ": " + describe_tile(e.id) + " at byte " + std::to_string(e.offset) +
                        ": index entry disagrees with its journal record");
  }
  if (stack_) {
    if (!cells.empty()) throw FormatError(name_ + ": a stack pack's journal holds cell records");
    return verify_stack();
  }
  // 2. Cells: each exactly once, agreeing with the skip grid.
  const uint32_t k = header_.skip_level;
  const size_t side = size_t(1) << k;
  if (cells.size() != side * side)
    throw FormatError(name_ + ": journal has " + std::to_string(cells.size()) + " cell records, the skip grid " +
                      std::to_string(side * side) + " cells");
  std::vector<uint8_t> seen(side * side, 0);
  for (const CellRecord& c : cells) {
    if (c.cx >= side || c.cy >= side || seen[c.cy * side + c.cx]++ || !(grid_.entry(c.cx, c.cy) == c.entry))
      throw FormatError(name_ + ": cell record (" + std::to_string(c.cx) + ", " + std::to_string(c.cy) +
                        ") repeated, out of range or disagreeing with the skip grid");
  }
  check_coarse_levels(cells);
  verify_tiles(open_tile);
}

void PackReader::verify_tiles(const TileOpener& open_tile) const {
  // 3. The page table reaches every tile exactly once; every tile decodes. The walk runs
  // one level past the finest so that entries at the finest level, which no pack may
  // hold, are visited and refused too.
  size_t reached = 0;
  const uint32_t map_level = header_.map_level;
  std::map<uint64_t, CutGrid> index_tiles;  // kept while the walk runs below them
  auto index_tile = [&](uint64_t id, const GridEntry& e) -> const CutGrid* {
    return &index_tiles.emplace(id, read_index_tile(id, e)).first->second;
  };
  const uint64_t past = uint64_t(1) << (map_level + 1);
  visit_page_tiles(grid_, map_level + 1, 0, 0, past, past, index_tile,
                   [&](uint64_t id, const GridEntry& e, uint32_t level, uint64_t, uint64_t) {
    auto t = find(id);
    if (!t || uint8_t(t->kind) != uint8_t(e.kind) || level >= map_level)
      throw FormatError(name_ + ": " + describe_tile(id) + " is named by the page table but missing from the index");
    ++reached;
    if (e.kind == EntryKind::index) return true;
    std::vector<uint8_t> raw = read_raw(id);
    if (!open_tile) return true;
    const std::string what = name_ + ": " + describe_tile(id) + " at byte " + std::to_string(t->offset);
    std::unique_ptr<Evaluator> ev;
    try {
      ev = open_tile(raw);
    } catch (const Error& err) {
      throw FormatError(what + ": " + err.what());
    }
    // (The tile's own root value may differ from its entry's: encodings that re-pick
    // values inside the admissible intervals (MMH, DAG-MH) do; the entry answers the
    // root's level.)
    if (ev->finest_level() != map_level - level) throw FormatError(what + ": wrong finest level");
    return true;
  });
  const size_t opaque = size_t(std::count_if(index_.begin(), index_.end(), [](auto& e) { return !is_deep_id(e.id); }));
  if (reached != opaque)
    throw FormatError(name_ + ": " + std::to_string(opaque - reached) + " tiles the page table never reaches");
  // 4. Deep tiles (load_deep matched them to the directory): each opens, of its side.
  for (const TileIndexEntry& e : index_) {
    if (e.kind != TileKind::deep) continue;
    const std::string what = name_ + ": " + describe_tile(e.id) + " at byte " + std::to_string(e.offset);
    const std::vector<uint8_t> raw = read_raw(e.id);
    const DeepTileView v = DeepTileView::open(raw, what);
    if (v.side_bits() != deep_->side_bits)
      throw FormatError(what + ": side 2^" + std::to_string(v.side_bits()) + ", the directory says 2^" +
                        std::to_string(deep_->side_bits));
  }
  // 5. The map preview holds exactly what the tiles answer at its levels (rebuilt from
  // them with the same levels and compared byte for byte).
  if (!open_tile || preview_->levels() == 0) return;
  std::map<uint64_t, std::pair<std::vector<uint8_t>, std::unique_ptr<Evaluator>>> opened;
  auto depth = [&](uint32_t level, uint64_t x, uint64_t y) -> float {
    const PageHit hit = walk_page_table(grid_, level, x, y, index_tile);
    if (hit.kind != PageHit::Kind::tile) return hit.value;
    auto it = opened.find(hit.tile);
    if (it == opened.end()) {
      if (opened.size() > 64) opened.clear();  // build() asks cell by cell
      std::vector<uint8_t> raw = read_raw(hit.tile);
      std::unique_ptr<Evaluator> ev = open_tile(raw);
      it = opened.emplace(hit.tile, std::make_pair(std::move(raw), std::move(ev))).first;
    }
    return it->second.second->depth(hit.rel, hit.tx, hit.ty);
  };
  const std::vector<uint8_t> want = MapPreview::build(grid_, preview_->levels(), depth).serialize();
  const uint64_t at = header_.grid_offset + CutGrid::serialized_size(header_.skip_level);
  const auto preview_begin = grid_bytes_.begin() + long(CutGrid::serialized_size(header_.skip_level));
  if (!std::equal(want.begin(), want.end(), preview_begin, preview_begin + long(preview_->serialized_size())))
    throw FormatError(where(at) + ": map preview differs from what the tiles answer at its levels");
}

void PackReader::check_depth_range() const {
  if (stack_) return check_stack_range();
  check_grid_range(grid_, name_ + ": skip grid at byte " + std::to_string(header_.grid_offset));
}

void PackReader::check_coarse_levels(const std::vector<CellRecord>& cells) const {
  // Each cell's entry lies in its own record's interval (cells were checked against the
  // grid: one record per cell); the coarse levels lie in the hulls of the records below
  // them (coarse_hulls.hpp).
  CellHulls hulls(header_.skip_level);
  for (const CellRecord& c : cells) {
    const std::string what = name_ + ": cell record (" + std::to_string(c.cx) + ", " + std::to_string(c.cy) + ")";
    if (!(c.lo <= c.hi))
      throw FormatError(what + ": interval [" + std::to_string(c.lo) + ", " + std::to_string(c.hi) + "] is empty");
    if (!(c.lo <= c.entry.value && c.entry.value <= c.hi))
      throw FormatError(what + ": entry value " + std::to_string(c.entry.value) + " lies outside its interval [" +
                        std::to_string(c.lo) + ", " + std::to_string(c.hi) + "]");
    hulls.set(c.cx, c.cy, c.lo, c.hi);
  }
  check_coarse_hulls(grid_, hulls, name_);
}

std::string PackReader::summary() const {
  uint64_t raw = 0, stored = 0, index_tiles = 0;
  uint32_t max_raw = 0;
  for (const TileIndexEntry& e : index_) {
    raw += e.raw_size;
    stored += e.stored_size;
    index_tiles += e.kind == TileKind::index;
    max_raw = std::max(max_raw, e.raw_size);
  }
  std::string features;
  const std::pair<uint32_t, const char*> names[] = {{kFeatureExitDepths, "exit_depths"}, {kFeatureHasTiles, "has_tiles"},
                                                    {kFeatureIndexTiles, "index_tiles"}, {kFeatureDeepShadow, "deep_shadow"},
                                                    {kFeatureStaticIntervals, "static_intervals"},
                                                    {kFeatureStack, "stack"},
                                                    {kFeatureDagmhDictionary, "dagmh_dictionary"},
                                                    {kFeatureCompressedGrid, "compressed_grid"},
                                                    {kFeaturePayloadsOnly, "payloads_only"},
                                                    {kFeatureMixedTiles, "mixed_tiles"},
                                                    {kFeatureStackSliceTiles, "stack_slice_tiles"},
                                                    {kFeaturePlaneTiles, "plane_tiles"},
                                                    {kFeatureStackGroupedTiles, "stack_grouped_tiles"},
                                                    {kFeaturePackedPlaneTiles, "packed_plane_tiles"},
                                                    {kFeaturePredictedPlaneLabels, "predicted_plane_labels"},
                                                    {kFeatureStackSplitCells, "stack_split_cells"},
                                                    {kFeatureWidePlaneBlocks, "wide_plane_blocks"}};
  for (auto [bit, n] : names)
    if (header_.flags & bit) features += std::string(features.empty() ? "" : ",") + n;
  char buf[512];
  std::string out = name_ + "\n";
  std::snprintf(buf, sizeof buf, "  version %u, encoding %s, light %s, map level %u (%llu texels a side), skip level %u\n",
                kPackVersion, to_string(header_.encoding).c_str(), light_kind_name(header_.light_kind),
                header_.map_level, (unsigned long long)(uint64_t(1) << header_.map_level), header_.skip_level);
  out += buf;
  std::snprintf(buf, sizeof buf, "  features %s, scene hash %016llx, tile_bytes %u\n",
                features.empty() ? "none" : features.c_str(), (unsigned long long)header_.scene_hash, header_.tile_bytes);
  out += buf;
  std::snprintf(buf, sizeof buf,
                "  %llu tiles (%llu index), %llu raw bytes (largest %u), %llu stored; grid %llu bytes; file %llu bytes\n",
                (unsigned long long)index_.size(), (unsigned long long)index_tiles, (unsigned long long)raw, max_raw,
                (unsigned long long)stored, (unsigned long long)header_.grid_size, (unsigned long long)file_size());
  out += buf;
  if (stack_) {
    out += stack_summary();
  } else {
    std::snprintf(buf, sizeof buf, "  map preview: %u levels below K, %zu cells, %zu values, %llu bytes (in the grid)\n",
                  preview_->levels(), preview_->cells(), preview_->stored_values(),
                  (unsigned long long)preview_->serialized_size());
    out += buf;
  }
  if (dictionary_) {
    const DictionaryCounts c = count_dictionary(*dictionary_);
    std::snprintf(buf, sizeof buf,
                  "  DAG-MH dictionary: %llu bytes (in the grid), %llu inner nodes (%llu words), %llu treelets, "
                  "CRC %08x\n",
                  (unsigned long long)c.bytes, (unsigned long long)c.nodes, (unsigned long long)c.node_words,
                  (unsigned long long)c.treelets, c.crc);
    out += buf;
  }
  if (deep_) {
    uint64_t draw = 0, dstored = 0;
    for (const TileIndexEntry& e : index_)
      if (is_deep_id(e.id)) draw += e.raw_size, dstored += e.stored_size;
    std::snprintf(buf, sizeof buf,
                  "  deep map: level %u (%llu texels a side), tiles of %u texels a side, %llu of %llu stored, "
                  "epsilon %g, %u^2 samples a texel; %llu raw bytes, %llu stored (directory included)\n",
                  deep_->level, (unsigned long long)(uint64_t(1) << deep_->level), 1u << deep_->side_bits,
                  (unsigned long long)deep_->tile_count(),
                  (unsigned long long)(uint64_t(deep_->tiles_per_side()) * deep_->tiles_per_side()),
                  double(deep_->epsilon), deep_->samples_per_side, (unsigned long long)draw,
                  (unsigned long long)dstored);
    out += buf;
  }
  for (auto& [k, v] : params_) out += "  " + printable_text(k) + " = " + printable_text(v) + "\n";
  return out;
}

}  // namespace st
