// PackWriter::finish with the pack-wide DAG-MH dictionary (tiles/PACK.md "DAG-MH
// dictionary"; DAG-MH 2021 §3.1 applied across tiles, tiles/core/DAGMH.md "Dictionary").
//
// The journal in "<path>.tmp" holds the tiles as each cell encoded them (version 1) and
// stays untouched: the pack is written afresh as "<path>.dict.tmp" (the journal copied
// cell by cell, each rewritten tile's record replaced by a record of its version-2
// bytes), renamed to "<path>", and only then is "<path>.tmp" removed. A build killed
// anywhere in between resumes from the same journal and gets the same pack: the tiles are
// shared in tile-id order, so the dictionary depends on the tiles alone, never on the
// order cells were appended in (a merged or MPI-built pack gets the same bytes).
#include "tiles/build/pack_writer.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <unordered_map>

#include "common/error.hpp"
#include "tiles/build/pack_file_io.hpp"
#include "tiles/build/dagmh_dictionary.hpp"
#include "tiles/core/pack_dictionary.hpp"

namespace st {

namespace {

using pack_io::sys_error;

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

bool PackWriter::finish_with_dictionary(PackHeader h, const std::vector<uint8_t>& grid_and_preview) {
  const std::string what = tmp_path();
  DictionaryOutcome& out = dictionary_;
  out = DictionaryOutcome{};
  if (params_.encoding != Encoding::dagmh) {
    out.skipped = "the encoding is " + to_string(params_.encoding) + ", not dagmh";
    return false;
  }
  // 1. Every encoded tile's raw bytes, in id order (tiles_ is sorted).
  std::vector<size_t> which;
  for (size_t i = 0; i < tiles_.size(); ++i)
    if (tiles_[i].kind == TileKind::encoded) which.push_back(i), out.raw_before += tiles_[i].raw_size;
  out.tiles = which.size();
  if (which.size() < 2) {
    out.skipped = "fewer than two encoded tiles";
    return false;
  }
  if (out.raw_before > params_.dictionary_max_input_bytes) {
    out.skipped = "the encoded tiles hold " + std::to_string(out.raw_before) + " raw bytes, above the dictionary pass's " +
                  std::to_string(params_.dictionary_max_input_bytes) + " (PackParams::dictionary_max_input_bytes)";
    return false;
  }
  std::vector<std::vector<uint8_t>> raw(which.size());
  for (size_t k = 0; k < which.size(); ++k) {
    const TileIndexEntry& t = tiles_[which[k]];
    std::vector<uint8_t> stored(t.stored_size);
    pack_io::pread_all(fd_, t.offset, stored, what);
    if (crc32_of(stored) != t.crc) throw Error(what + ": " + describe_tile(t.id) + " fails its CRC on the read back");
    raw[k] = zlib_decompress(stored, t.raw_size, what + ": " + describe_tile(t.id));
  }
  // 2. Share; a dictionary above the pack bound shares only subtrees found in more tiles.
  dagmh::SharedTiles shared;
  for (out.min_tiles = 2;; out.min_tiles *= 2) {
    shared = dagmh::share_across_tiles(raw, out.min_tiles);
    if (shared.dictionary.size() <= kMaxPackDictionaryBytes) break;
    if (out.min_tiles > (1u << 30)) throw Error(what + ": the DAG-MH dictionary does not fit its bound");
  }
  if (shared.dictionary.empty() || shared.tiles_rewritten == 0) {
    out.skipped = "no subtree occurs in two tiles";
    return false;
  }
  std::unordered_map<uint64_t, size_t> rewritten;  // tile id -> k
  for (size_t k = 0; k < which.size(); ++k) {
    // A rewritten tile never grows (its own nodes are a subset, its skip table no
    // larger); should one, the original (version 1, valid in any pack) is kept.
    if (shared.tiles[k].size() > params_.tile_bytes || shared.tiles[k] == raw[k]) continue;
    rewritten.emplace(tiles_[which[k]].id, k);
  }
  raw.clear();
  raw.shrink_to_fit();
  out.bytes = shared.dictionary.size();
  out.tiles_rewritten = rewritten.size();
  for (size_t k = 0; k < which.size(); ++k) {
    const auto it = rewritten.find(tiles_[which[k]].id);
    out.raw_after += it != rewritten.end() ? shared.tiles[k].size() : tiles_[which[k]].raw_size;
  }

  // 3. The new file: header (building) and params, then the journal cell by cell.
  OutFile f(path_ + ".dict.tmp");
  try {
    PackHeader building = base_header();
    f.write_at(0, building.serialize());
    f.write_at(building.params_offset, serialize_params(params_.build_params));
    f.end = building.journal_offset;
    std::vector<TileIndexEntry> index;
    index.reserve(tiles_.size());
    std::vector<uint8_t> span;
    auto copy_record = [&](const TileIndexEntry& t) {
      span.resize(kRecordBytes + t.stored_size);
      pack_io::pread_all(fd_, t.offset - kRecordBytes, span, what);
      index.push_back(t);
      index.back().offset = f.end + kRecordBytes;
      f.append(span);
    };
    size_t cells = 0;
    replay_journal(fd_, h.journal_offset, end_, params_, what,
                   [&](const CellRecord&, std::vector<TileIndexEntry>&& tiles, uint64_t, uint64_t span_end) {
                     for (const TileIndexEntry& t : tiles) {
                       const auto it = t.kind == TileKind::encoded ? rewritten.find(t.id) : rewritten.end();
                       if (it == rewritten.end()) {
                         copy_record(t);
                         continue;
                       }
                       const std::vector<uint8_t>& v2 = shared.tiles[it->second];
                       const std::vector<uint8_t> stored = zlib_compress(v2, params_.compression_level);
                       const TileRecord r{t.kind, t.id, uint32_t(stored.size()), uint32_t(v2.size()), crc32_of(stored)};
                       f.append(r.serialize());
                       index.push_back(TileIndexEntry{t.id, f.end, r.stored_size, r.raw_size, r.crc, t.kind});
                       f.append(stored);
                     }
                     std::array<uint8_t, kRecordBytes> cell{};
                     pack_io::pread_all(fd_, span_end - kRecordBytes, cell, what);
                     f.append(cell);
                     ++cells;
                     return true;
                   });
    if (cells != cells_.size())
      throw Error(what + ": the journal replays " + std::to_string(cells) + " cells on the dictionary pass, " +
                  std::to_string(cells_.size()) + " were appended");
    for (const TileIndexEntry& t : tiles_)  // the deep part follows the last cell (append_deep_tile)
      if (t.kind == TileKind::deep || t.kind == TileKind::deep_directory) copy_record(t);
    if (index.size() != tiles_.size())
      throw Error(what + ": the dictionary pass copied " + std::to_string(index.size()) + " of " +
                  std::to_string(tiles_.size()) + " tiles");
    std::sort(index.begin(), index.end(), [](auto& a, auto& b) { return a.id < b.id; });

    // 4. Grid section (skip grid, preview, dictionary), index, header last.
    h.flags |= kFeatureDagmhDictionary;
    h.grid_offset = (f.end + 7) & ~uint64_t(7);
    f.append(std::vector<uint8_t>(h.grid_offset - f.end, 0));
    std::vector<uint8_t> grid_bytes = grid_and_preview;
    const std::vector<uint8_t> dict = dictionary_section(shared.dictionary, params_.compression_level);
    grid_bytes.insert(grid_bytes.end(), dict.begin(), dict.end());
    const std::vector<uint8_t> index_bytes = serialize_index(index);
    if (params_.compress_grid) {  // stored as one zlib stream (tiles/PACK.md "Compressed grid section")
      h.flags |= kFeatureCompressedGrid;
      grid_bytes = compress_grid_section(grid_bytes, params_.compression_level);
    }
    h.grid_size = grid_bytes.size();
    h.grid_crc = crc32_of(grid_bytes);
    h.index_offset = h.grid_offset + h.grid_size;
    h.tile_count = index.size();
    h.index_crc = crc32_of(index_bytes);
    h.state = PackState::complete;
    f.append(grid_bytes);
    f.append(index_bytes);
    if (::ftruncate(f.fd, off_t(h.file_size())) != 0) throw Error(sys_error(f.path + ": truncate"));
    f.sync();
    f.write_at(0, h.serialize());
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
  pack_io::fsync_dir_of(path_);
  finished_ = true;
  return true;
}

}  // namespace st
