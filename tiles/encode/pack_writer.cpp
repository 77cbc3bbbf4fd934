#include "tiles/encode/pack_writer.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <unordered_map>

#include "common/error.hpp"
#include "tiles/encode/pack_file_io.hpp"
#include "tiles/core/interval.hpp"
#include "tiles/core/encoding.hpp"
#include "tiles/core/map_preview.hpp"
#include "tiles/core/page_table.hpp"
#include "tiles/core/pack_dictionary.hpp"
#include "tiles/core/plane_pack.hpp"
#include "tiles/core/plane_tile.hpp"

namespace st {

namespace {

using pack_io::fsync_dir_of;
using pack_io::pread_all;
using pack_io::sys_error;

}  // namespace

PackParams PackParams::from(const LightSpace& light, const CutParams& cut) {
  PackParams p;
  p.light_kind = light.kind();
  p.light = light.to_array();
  p.map_level = cut.map_level;
  p.skip_level = cut.skip_level;
  p.encoding = cut.codec.encoding;
  p.tile_bytes = cut.tile_bytes;
  return p;
}

PackWriter::PackWriter(std::string path, PackParams params) : path_(std::move(path)), params_(std::move(params)) {
  if (params_.map_level > kMaxLevel || params_.skip_level > std::min(params_.map_level, kMaxSkipLevel))
    throw Error(path_ + ": bad map/skip level " + std::to_string(params_.map_level) + "/" +
                std::to_string(params_.skip_level));
  if (params_.tile_bytes < kMinTileBytes || params_.tile_bytes > kMaxTileBytes)
    throw Error(path_ + ": tile_bytes " + std::to_string(params_.tile_bytes) + " outside " + tile_bytes_bounds());
  if (params_.features & ~uint32_t(kFeatureExitDepths | kFeatureStaticIntervals))
    throw Error(path_ + ": features may only name exit_depths / static_intervals (the rest are derived: "
                "deep_shadow from append_deep_tile)");
  if (params_.compression_level < 0 || params_.compression_level > 12)
    throw Error(path_ + ": compression level outside 0..12");
  done_.assign(size_t(1) << (2 * params_.skip_level), 0);
}

PackWriter::~PackWriter() {
  if (fd_ >= 0) ::close(fd_);
}

PackHeader PackWriter::base_header() const {
  PackHeader h;
  h.state = PackState::building;
  h.flags = params_.features;
  h.encoding = params_.encoding;
  h.light_kind = params_.light_kind;
  h.map_level = params_.map_level;
  h.skip_level = params_.skip_level;
  h.tile_bytes = params_.tile_bytes;
  h.scene_hash = params_.scene_hash;
  h.light = params_.light;
  std::vector<uint8_t> blob = serialize_params(params_.build_params);
  h.params_offset = kPackHeaderBytes;
  h.params_size = blob.size();
  h.params_crc = crc32_of(blob);
  h.journal_offset = h.params_offset + h.params_size;
  return h;
}

void PackWriter::write_at(uint64_t offset, std::span<const uint8_t> bytes) {
  try {
    pack_io::pwrite_all(fd_, offset, bytes, tmp_path());
  } catch (const Error&) {
    failed_ = true;
    throw;
  }
}

std::unique_ptr<PackWriter> PackWriter::create(const std::string& path, const PackParams& params) {
  std::unique_ptr<PackWriter> w(new PackWriter(path, params));
  w->open_new();
  return w;
}

std::unique_ptr<PackWriter> PackWriter::resume(const std::string& path, const PackParams& params) {
  std::unique_ptr<PackWriter> w(new PackWriter(path, params));
  w->open_existing();
  return w;
}

std::unique_ptr<PackWriter> PackWriter::create_or_resume(const std::string& path, const PackParams& params) {
  struct stat st{};
  if (::stat((path + ".tmp").c_str(), &st) == 0) return resume(path, params);
  return create(path, params);
}

void PackWriter::open_new() {
  fd_ = ::open(tmp_path().c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd_ < 0) throw Error(sys_error(tmp_path() + ": cannot create"));
  PackHeader h = base_header();
  auto head = h.serialize();
  write_at(0, head);
  write_at(h.params_offset, serialize_params(params_.build_params));
  end_ = h.journal_offset;
}

void PackWriter::open_existing() {
  const std::string what = tmp_path();
  fd_ = ::open(what.c_str(), O_RDWR | O_CLOEXEC);
  if (fd_ < 0) throw Error(sys_error(what + ": cannot reopen for resume"));
  struct stat st{};
  if (::fstat(fd_, &st) != 0) throw Error(sys_error(what + ": stat"));
  const uint64_t file_size = uint64_t(st.st_size);
  std::array<uint8_t, kPackHeaderBytes> head{};
  if (file_size < kPackHeaderBytes) throw Error(what + ": too short to resume (" + std::to_string(file_size) + " bytes)");
  pread_all(fd_, 0, head, what);
  PackHeader found = PackHeader::parse(head, what);
  PackHeader want = base_header();
  auto mismatch = [&](const char* field) {
    throw Error(what + ": cannot resume: " + field + " differs from this build's parameters");
  };
  if (found.encoding != want.encoding) mismatch("encoding");
  if (found.light_kind != want.light_kind || found.light != want.light) mismatch("light");
  if (found.map_level != want.map_level) mismatch("map level");
  if (found.skip_level != want.skip_level) mismatch("skip level");
  if (found.tile_bytes != want.tile_bytes) mismatch("tile_bytes");
  if (found.scene_hash != want.scene_hash) mismatch("scene hash");
  if ((found.flags & (kFeatureExitDepths | kFeatureDeepShadow)) != want.flags) mismatch("features");
  if (found.params_size != want.params_size || found.params_crc != want.params_crc) mismatch("build parameters");
  std::vector<uint8_t> blob(found.params_size);
  if (file_size < found.journal_offset) throw Error(what + ": truncated inside the build parameters");
  pread_all(fd_, found.params_offset, blob, what);
  if (blob != serialize_params(params_.build_params)) mismatch("build parameters");

  // Replay the journal: keep every complete cell, cut the file after the last one.
  const size_t side = size_t(1) << params_.skip_level;
  const uint64_t good_end = replay_journal(
      fd_, found.journal_offset, file_size, params_, what,
      [&](const CellRecord& c, std::vector<TileIndexEntry>&& tiles, uint64_t, uint64_t) {
        if (done_[size_t(c.cy) * side + c.cx]) return false;
        done_[size_t(c.cy) * side + c.cx] = 1;
        cells_.push_back(c);
        tiles_.insert(tiles_.end(), tiles.begin(), tiles.end());
        return true;
      });
  resumed_cells_ = cells_.size();
  truncated_bytes_ = file_size - good_end;
  if (::ftruncate(fd_, off_t(good_end)) != 0) throw Error(sys_error(what + ": truncate the torn tail"));
  // A .tmp that was completed but not renamed is rewritten as "building" here.
  write_at(0, want.serialize());
  end_ = good_end;
}

std::vector<CellRecord> PackWriter::cells() const {
  std::lock_guard lock(mu_);
  return cells_;
}

bool PackWriter::is_done(uint32_t cx, uint32_t cy) const {
  std::lock_guard lock(mu_);
  size_t side = size_t(1) << params_.skip_level;
  return cx < side && cy < side && done_[size_t(cy) * side + cx];
}

void PackWriter::append_cell(const CutCell& cell) {
  const size_t side = size_t(1) << params_.skip_level;
  if (cell.cx >= side || cell.cy >= side)
    throw Error(tmp_path() + ": cell (" + std::to_string(cell.cx) + ", " + std::to_string(cell.cy) +
                ") outside the skip grid");
  // Compress outside the lock: this is the expensive part of appending.
  append_cell_bytes(encode_cell_bytes(cell, params_));
}

void PackWriter::append_cell_bytes(std::span<const uint8_t> bytes) {
  std::vector<TileIndexEntry> entries;
  const CellRecord rec = parse_cell_bytes(bytes, params_, tmp_path(), entries);
  const size_t side = size_t(1) << params_.skip_level;
  std::lock_guard lock(mu_);
  const std::string where = tmp_path() + ": cell (" + std::to_string(rec.cx) + ", " + std::to_string(rec.cy) + ")";
  if (failed_ || finished_) throw Error(where + ": writer already failed or finished");
  size_t i = size_t(rec.cy) * side + rec.cx;
  if (done_[i]) throw Error(where + " appended twice");
  write_at(end_, bytes);
  for (TileIndexEntry& e : entries) e.offset += end_;
  end_ += bytes.size();
  tiles_.insert(tiles_.end(), entries.begin(), entries.end());
  cells_.push_back(rec);
  done_[i] = 1;
}

void PackWriter::append_deep_tile(uint64_t id, TileKind kind, std::span<const uint8_t> raw) {
  const std::string where = tmp_path() + ": " + describe_tile(id);
  if ((kind != TileKind::deep && kind != TileKind::deep_directory) || !id_fits_kind(id, kind))
    throw Error(where + ": not a deep tile id of kind " + std::to_string(int(kind)));
  if (raw.empty() || raw.size() > params_.tile_bytes)
    throw Error(where + " has " + std::to_string(raw.size()) + " bytes (tile_bytes " +
                std::to_string(params_.tile_bytes) + "): raise --tile-bytes or the deep epsilon, or shrink the deep tiles");
  std::vector<uint8_t> stored = zlib_compress(raw, params_.compression_level);
  TileRecord r{kind, id, uint32_t(stored.size()), uint32_t(raw.size()), crc32_of(stored)};
  auto head = r.serialize();
  std::lock_guard lock(mu_);
  if (failed_ || finished_) throw Error(where + ": writer already failed or finished");
  if (cells_.size() != done_.size()) throw Error(where + ": deep tiles go after the last cell");
  write_at(end_, head);
  write_at(end_ + kRecordBytes, stored);
  tiles_.push_back(TileIndexEntry{id, end_ + kRecordBytes, r.stored_size, r.raw_size, r.crc, kind});
  end_ += kRecordBytes + stored.size();
}

// The synced journal `what` becomes path_: closed, renamed, the directory synced.
void PackWriter::publish(const std::string& what) {
  ::close(fd_);
  fd_ = -1;
  if (::rename(what.c_str(), path_.c_str()) != 0) throw Error(sys_error(what + ": rename to " + path_));
  fsync_dir_of(path_);
  finished_ = true;
}

void PackWriter::finish_part() {
  std::lock_guard lock(mu_);
  const std::string what = tmp_path();
  if (failed_ || finished_) throw Error(what + ": writer already failed or finished");
  if (::fsync(fd_) != 0) throw Error(sys_error(what + ": fsync"));
  publish(what);
}

void PackWriter::finish(const CutGrid& grid) {
  std::lock_guard lock(mu_);
  const std::string what = tmp_path();
  if (failed_ || finished_) throw Error(what + ": writer already failed or finished");
  const size_t side = size_t(1) << params_.skip_level;
  if (cells_.size() != side * side)
    throw Error(what + ": finish with " + std::to_string(cells_.size()) + " of " + std::to_string(side * side) +
                " cells done");
  if (grid.levels != params_.skip_level || grid.entries.size() != side * side ||
      grid.coarse.size() != CutGrid::coarse_count(grid.levels))
    throw Error(what + ": skip grid does not have the skip level's shape");
  for (const CellRecord& c : cells_) {
    const GridEntry& e = grid.entry(c.cx, c.cy);
    if (!(e == c.entry))
      throw Error(what + ": skip grid entry (" + std::to_string(c.cx) + ", " + std::to_string(c.cy) +
                  ") differs from its cell's");
  }
  std::sort(tiles_.begin(), tiles_.end(), [](auto& a, auto& b) { return a.id < b.id; });
  for (size_t i = 1; i < tiles_.size(); ++i)
    if (tiles_[i].id == tiles_[i - 1].id) throw Error(what + ": " + describe_tile(tiles_[i].id) + " appended twice");

  PackHeader h = base_header();
  const bool deep_tiles = std::any_of(tiles_.begin(), tiles_.end(), [](auto& t) { return t.kind == TileKind::deep; });
  const bool deep_dir = !tiles_.empty() && tiles_.back().kind == TileKind::deep_directory;  // sorted: the last id
  if (deep_tiles != deep_dir) throw Error(what + ": deep tiles need a deep directory and a directory needs tiles");
  if (deep_dir) h.flags |= kFeatureDeepShadow;
  bool index_tiles = std::any_of(tiles_.begin(), tiles_.end(), [](auto& t) { return t.kind == TileKind::index; });
  h.flags |= (tiles_.empty() ? 0u : uint32_t(kFeatureHasTiles)) | (index_tiles ? uint32_t(kFeatureIndexTiles) : 0u);
  std::vector<uint8_t> grid_bytes = grid.serialize();
  const std::vector<uint8_t> preview = preview_bytes(grid);
  grid_bytes.insert(grid_bytes.end(), preview.begin(), preview.end());
  const uint32_t kinds = tile_kind_features();
  const bool mixed = kinds & kFeatureMixedTiles;
  h.flags |= kinds;
  RewrittenTiles rewritten;
  if (params_.dagmh_dictionary) {
    const std::vector<uint8_t> dict = share_dictionary(rewritten, mixed);
    if (!dict.empty()) {
      h.flags |= kFeatureDagmhDictionary;
      const std::vector<uint8_t> section = dictionary_section(dict, params_.compression_level);
      grid_bytes.insert(grid_bytes.end(), section.begin(), section.end());
    }
  }
  if (params_.journal_records) return finish_with_records(h, std::move(grid_bytes), rewritten);
  write_finished(h, std::move(grid_bytes), rewritten);
}

namespace {

// The header of a complete pack whose tile data ends at `end`: the grid section 8-aligned
// after it (compressed first when the params say so), the index right after the grid.
// Returns the zero padding to write between `end` and the grid.
std::vector<uint8_t> seal_header(PackHeader& h, const PackParams& params, uint64_t end,
                                 std::vector<uint8_t>& grid_bytes, std::span<const uint8_t> index_bytes,
                                 uint64_t tile_count) {
  h.grid_offset = (end + 7) & ~uint64_t(7);
  if (params.compress_grid) {  // stored as one zlib stream (tiles/PACK.md "Compressed grid section")
    h.flags |= kFeatureCompressedGrid;
    grid_bytes = compress_grid_section(grid_bytes, params.compression_level);
  }
  h.grid_size = grid_bytes.size();
  h.grid_crc = crc32_of(grid_bytes);
  h.index_offset = h.grid_offset + h.grid_size;
  h.tile_count = tile_count;
  h.index_crc = crc32_of(index_bytes);
  h.state = PackState::complete;
  return std::vector<uint8_t>(h.grid_offset - end, 0);
}

}  // namespace

void PackWriter::finish_with_records(PackHeader h, std::vector<uint8_t> grid_bytes, const RewrittenTiles& rewritten) {
  const std::string what = tmp_path();
  if (!rewritten.empty()) throw Error(what + ": journal_records cannot keep tiles the DAG-MH dictionary rewrote");
  // In place: the journal as it is, padding, grid, the plain index, the header last.
  const std::vector<uint8_t> index_bytes = serialize_index(tiles_);
  write_at(end_, seal_header(h, params_, end_, grid_bytes, index_bytes, tiles_.size()));
  write_at(h.grid_offset, grid_bytes);
  write_at(h.index_offset, index_bytes);
  if (::ftruncate(fd_, off_t(h.file_size())) != 0) throw Error(sys_error(what + ": truncate"));
  if (::fsync(fd_) != 0) throw Error(sys_error(what + ": fsync"));
  write_at(0, h.serialize());  // until it says "complete" the file is a resumable journal
  if (::fsync(fd_) != 0) throw Error(sys_error(what + ": fsync"));
  publish(what);
}

namespace {

// The new file: appends at `end`, closes on destruction unless kept.
struct OutFile {
  std::string path;
  int fd = -1;
  uint64_t end = 0;
  explicit OutFile(std::string p) : path(std::move(p)) {
    fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (fd < 0) throw Error(sys_error(path + ": cannot create"));
  }
  ~OutFile() {
    if (fd >= 0) ::close(fd);
  }
  void write_at(uint64_t offset, std::span<const uint8_t> bytes) { pack_io::pwrite_all(fd, offset, bytes, path); }
  void append(std::span<const uint8_t> bytes) {
    write_at(end, bytes);
    end += bytes.size();
  }
  void sync() {
    if (::fsync(fd) != 0) throw Error(sys_error(path + ": fsync"));
  }
};

}  // namespace

void PackWriter::write_finished(PackHeader h, std::vector<uint8_t> grid_bytes, const RewrittenTiles& rewritten) {
  const std::string what = tmp_path();
  OutFile f(path_ + ".final.tmp");
  try {
    f.write_at(0, base_header().serialize());  // state building until the end
    f.write_at(h.params_offset, serialize_params(params_.build_params));
    f.end = h.journal_offset;
    // The payloads alone, in id order (tiles_ is sorted): tiles/PACK.md "Payloads only".
    std::vector<TileIndexEntry> index;
    index.reserve(tiles_.size());
    std::vector<uint8_t> stored;
    auto next = rewritten.begin();
    for (const TileIndexEntry& t : tiles_) {
      TileIndexEntry e = t;
      if (next != rewritten.end() && next->first == t.id) {
        stored = zlib_compress(next->second, params_.compression_level);
        e.raw_size = uint32_t(next->second.size());
        ++next;
      } else {
        stored.resize(t.stored_size);
        pread_all(fd_, t.offset, stored, what);
        if (crc32_of(stored) != t.crc) throw Error(what + ": " + describe_tile(t.id) + " fails its CRC on the read back");
      }
      e.offset = f.end;
      e.stored_size = uint32_t(stored.size());
      e.crc = crc32_of(stored);
      index.push_back(e);
      f.append(stored);
    }
    if (next != rewritten.end()) throw Error(what + ": a rewritten tile is not in the journal");
    h.flags |= kFeaturePayloadsOnly;
    const std::vector<uint8_t> index_bytes = serialize_compact_index(index, params_.compression_level);
    f.append(seal_header(h, params_, f.end, grid_bytes, index_bytes, index.size()));
    f.append(grid_bytes);
    f.append(index_bytes);
    if (::ftruncate(f.fd, off_t(f.end)) != 0) throw Error(sys_error(f.path + ": truncate"));
    f.sync();
    f.write_at(0, h.serialize());  // header last
    f.sync();
  } catch (...) {
    ::unlink(f.path.c_str());  // the journal in .tmp is untouched: resume or finish again
    throw;
  }
  ::close(f.fd);
  f.fd = -1;
  if (::rename(f.path.c_str(), path_.c_str()) != 0) throw Error(sys_error(f.path + ": rename to " + path_));
  // The pack is in place: the journal it came from goes (a build killed before this line
  // leaves both; resuming that .tmp writes the same pack again).
  ::close(fd_);
  fd_ = -1;
  ::unlink(what.c_str());
  fsync_dir_of(path_);
  finished_ = true;
}

uint32_t PackWriter::tile_kind_features() const {
  const std::string what = tmp_path();
  uint32_t flags = 0;
  for (const TileIndexEntry& t : tiles_) {
    if (t.kind != TileKind::encoded) continue;
    std::vector<uint8_t> stored(t.stored_size);
    pack_io::pread_all(fd_, t.offset, stored, what);
    if (crc32_of(stored) != t.crc) throw Error(what + ": " + describe_tile(t.id) + " fails its CRC on the read back");
    std::vector<uint8_t> raw = zlib_decompress(stored, t.raw_size, what + ": " + describe_tile(t.id));
    flags |= plane_tile_features(raw);  // packed forms, version 3 (wide labelled blocks)
    if (is_packed_plane_tile(raw)) unpack_plane_tile(raw);
    std::span<const uint8_t> tile = raw;
    if (is_plane_buffer(tile)) {
      flags |= kFeaturePlaneTiles;
      tile = validate_plane_tile(tile).inner;
    }
    if (params_.encoding == Encoding::dagmh && is_mmh_buffer(tile)) flags |= kFeatureMixedTiles;
  }
  return flags;
}

std::vector<uint8_t> PackWriter::preview_bytes(const CutGrid& grid) const {
  const std::string what = tmp_path();
  // The full pack's answer at (level, x, y) under a non-constant entry: the page-table
  // walk over the journal's tiles, read back and opened (a few at a time: build() asks
  // cell by cell).
  struct Open {
    std::vector<uint8_t> raw;
    std::unique_ptr<Evaluator> ev;
    CutGrid grid;
  };
  std::unordered_map<uint64_t, Open> open;
  auto tile = [&](uint64_t id) -> Open& {
    auto it = open.find(id);
    if (it != open.end()) return it->second;
    if (open.size() > 64) open.clear();
    auto t = std::lower_bound(tiles_.begin(), tiles_.end(), id, [](const TileIndexEntry& e, uint64_t i) { return e.id < i; });
    if (t == tiles_.end() || t->id != id) throw Error(what + ": map preview: " + describe_tile(id) + " is not in the journal");
    std::vector<uint8_t> stored(t->stored_size);
    pread_all(fd_, t->offset, stored, what);
    Open o;
    o.raw = zlib_decompress(stored, t->raw_size, what + ": " + describe_tile(id));
    if (t->kind == TileKind::encoded && is_packed_plane_tile(o.raw)) unpack_plane_tile(o.raw);
    if (t->kind == TileKind::encoded) o.ev = open_encoded(params_.encoding, o.raw);
    else o.grid = CutGrid::parse(o.raw, what + ": " + describe_tile(id), kMaxIndexLevels);
    return open.emplace(id, std::move(o)).first->second;
  };
  auto depth = [&](uint32_t level, uint64_t x, uint64_t y) -> float {
    const PageHit hit = walk_page_table(grid, level, x, y, [&](uint64_t id, const GridEntry&) { return &tile(id).grid; });
    if (hit.kind != PageHit::Kind::tile) return hit.value;
    return tile(hit.tile).ev->depth(hit.rel, hit.tx, hit.ty);
  };
  uint32_t p = std::min(params_.preview_levels,
                        std::min(kMaxPreviewLevels, params_.map_level - params_.skip_level));
  for (;; --p) {
    MapPreview m = MapPreview::build(grid, p, depth);
    if (p == 0 || m.serialized_size() <= std::min(params_.preview_max_bytes, kMaxPreviewBytes)) return m.serialize();
  }
}

std::vector<uint8_t> encode_cell_bytes(const CutCell& cell, const PackParams& params) {
  const std::string where = "cell (" + std::to_string(cell.cx) + ", " + std::to_string(cell.cy) + ")";
  std::vector<uint8_t> buf;
  for (const CutTile& t : cell.tiles) {
    if (t.raw.empty() || t.raw.size() > params.tile_bytes)
      throw Error(where + ": " + describe_tile(t.id) + " has " + std::to_string(t.raw.size()) +
                  " bytes (tile_bytes " + std::to_string(params.tile_bytes) + ")");
    std::vector<uint8_t> stored = zlib_compress(t.raw, params.compression_level);
    if (params.pack_plane_tiles && t.kind == TileKind::encoded && is_plane_buffer(t.raw)) {
      // The same size; empty if it does not round-trip.
      const std::vector<uint8_t> packed = pack_plane_tile(t.raw, nullptr, params.predict_plane_labels);
      if (!packed.empty()) {
        std::vector<uint8_t> z = zlib_compress(packed, params.compression_level);
        if (z.size() < stored.size()) stored = std::move(z);
      }
    }
    TileRecord r{t.kind, t.id, uint32_t(stored.size()), uint32_t(t.raw.size()), crc32_of(stored)};
    auto head = r.serialize();
    buf.insert(buf.end(), head.begin(), head.end());
    buf.insert(buf.end(), stored.begin(), stored.end());
  }
  uint64_t root_id = make_tile_id(params.skip_level, cell.cx, cell.cy);
  bool has_tile = cell.entry.kind != EntryKind::constant;
  if (has_tile != (!cell.tiles.empty() && cell.tiles.back().id == root_id &&
                   uint8_t(cell.tiles.back().kind) == uint8_t(cell.entry.kind)))
    throw Error(where + ": entry kind disagrees with its tiles (the cell's own tile must come last)");
  CellRecord rec{cell.cx, cell.cy, cell.entry, cell.lo, cell.hi};
  auto head = rec.serialize();
  buf.insert(buf.end(), head.begin(), head.end());
  return buf;
}

namespace {

// The checks of one cell's records, shared by replay (which stops at the first failure:
// a torn tail) and append_cell_bytes (which refuses the span). Returns "" when `tiles`
// and the cell record form one valid cell of `params`.
std::string cell_problem(const CellRecord& c, const std::vector<TileIndexEntry>& tiles, const PackParams& params) {
  const size_t side = size_t(1) << params.skip_level;
  if (c.cx >= side || c.cy >= side) return "cell outside the skip grid";
  bool has_tile = c.entry.kind != EntryKind::constant;
  uint64_t root_id = make_tile_id(params.skip_level, c.cx, c.cy);
  bool root_found = !tiles.empty() && tiles.back().id == root_id && uint8_t(tiles.back().kind) == uint8_t(c.entry.kind);
  if (has_tile != root_found || (!has_tile && !tiles.empty()))
    return "cell entry disagrees with its tiles (its own tile must come last)";
  for (const TileIndexEntry& t : tiles)
    if (t.kind != TileKind::encoded && t.kind != TileKind::index) return "a deep tile among a cell's records";
  return "";
}

}  // namespace

CellRecord parse_cell_bytes(std::span<const uint8_t> bytes, const PackParams& params, const std::string& what,
                            std::vector<TileIndexEntry>& tiles) {
  tiles.clear();
  uint64_t pos = 0;
  auto fail = [&](const std::string& why) -> CellRecord {
    throw Error(what + ": cell span byte " + std::to_string(pos) + ": " + why);
  };
  while (bytes.size() - pos >= kRecordBytes) {
    TileRecord t;
    CellRecord c;
    RecordType type = parse_record(bytes.subspan(pos).first<kRecordBytes>(), &t, &c);
    if (type == RecordType::tile) {
      if (t.raw_size > params.tile_bytes) return fail(describe_tile(t.id) + " exceeds tile_bytes");
      if (bytes.size() - pos - kRecordBytes < t.stored_size) return fail(describe_tile(t.id) + " is truncated");
      if (crc32_of(bytes.subspan(pos + kRecordBytes, t.stored_size)) != t.crc)
        return fail(describe_tile(t.id) + " fails its CRC");
      tiles.push_back(TileIndexEntry{t.id, pos + kRecordBytes, t.stored_size, t.raw_size, t.crc, t.kind});
      pos += kRecordBytes + t.stored_size;
    } else if (type == RecordType::cell) {
      std::string problem = cell_problem(c, tiles, params);
      if (!problem.empty()) return fail(problem);
      pos += kRecordBytes;
      if (pos != bytes.size()) return fail("trailing bytes after the cell record");
      return c;
    } else {
      return fail("not a valid tile or cell record");
    }
  }
  return fail("no cell record at the end");
}

uint64_t replay_journal(int fd, uint64_t begin, uint64_t file_size, const PackParams& params,
                        const std::string& what, const JournalCellFn& on_cell) {
  // Tiles are pending until their cell's record follows.
  uint64_t pos = begin, good_end = begin;
  std::vector<TileIndexEntry> pending;
  std::vector<uint8_t> payload;
  while (file_size >= pos && file_size - pos >= kRecordBytes) {
    std::array<uint8_t, kRecordBytes> rec{};
    pread_all(fd, pos, rec, what);
    TileRecord t;
    CellRecord c;
    RecordType type = parse_record(rec, &t, &c);
    if (type == RecordType::tile) {
      if (t.raw_size > params.tile_bytes || file_size - pos - kRecordBytes < t.stored_size) break;
      payload.resize(t.stored_size);
      pread_all(fd, pos + kRecordBytes, payload, what);
      if (crc32_of(payload) != t.crc) break;
      pending.push_back(TileIndexEntry{t.id, pos + kRecordBytes, t.stored_size, t.raw_size, t.crc, t.kind});
      pos += kRecordBytes + t.stored_size;
    } else if (type == RecordType::cell) {
      if (!cell_problem(c, pending, params).empty()) break;
      pos += kRecordBytes;
      if (!on_cell(c, std::move(pending), good_end, pos)) break;
      pending.clear();
      good_end = pos;
    } else {
      break;
    }
  }
  return good_end;
}

void write_pack(const std::string& path, const Hierarchy& h, const CutParams& cut, const PackParams& params) {
  if (params.map_level != cut.map_level || params.skip_level != cut.skip_level ||
      params.tile_bytes != cut.tile_bytes || params.encoding != cut.codec.encoding)
    throw Error(path + ": pack and cut parameters disagree");
  auto w = PackWriter::create(path, params);
  CutGrid grid = cut_hierarchy(h, cut, [&](CutCell&& c) { w->append_cell(c); });
  w->finish(grid);
}

}  // namespace st
