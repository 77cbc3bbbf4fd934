#include "tiles/encode/pack_merge.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cstring>
#include <memory>
#include <vector>

#include "common/error.hpp"
#include "tiles/encode/hierarchy.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/encode/pack_writer.hpp"
#include "tiles/encode/tile_cut.hpp"

namespace st {

BuildShard BuildShard::parse(const std::string& text) {
  const std::string bad = "--shard: expected I/N with 0 <= I < N <= " + std::to_string(kMaxShards) + ", got '" +
                          text + "'";
  size_t slash = text.find('/');
  if (slash == std::string::npos) throw Error(bad);
  BuildShard s;
  const char* b = text.data();
  auto [p1, e1] = std::from_chars(b, b + slash, s.index);
  auto [p2, e2] = std::from_chars(b + slash + 1, b + text.size(), s.count);
  if (e1 != std::errc() || e2 != std::errc() || p1 != b + slash || p2 != b + text.size() || slash == 0 ||
      s.count == 0 || s.count > kMaxShards || s.index >= s.count)
    throw Error(bad);
  return s;
}

uint64_t BuildShard::cell_count(uint32_t skip_level) const {
  const uint64_t cells = uint64_t(1) << (2 * skip_level);
  return cells / count + (index < cells % count ? 1 : 0);
}

namespace {

// One part file, opened read-only: its header, its shard and the build parameters a
// merged pack keeps (everything but the shard).
struct Part {
  std::string path;
  int fd = -1;
  uint64_t size = 0;
  PackHeader header;
  BuildShard shard;
  PackParams params;  // the merged pack's: no shard parameter
  Part() = default;
  Part(const Part&) = delete;
  Part& operator=(const Part&) = delete;
  ~Part() {
    if (fd >= 0) ::close(fd);
  }
};

void pread_exact(const Part& p, uint64_t offset, std::span<uint8_t> out) {
  size_t done = 0;
  while (done < out.size()) {
    ssize_t n = ::pread(p.fd, out.data() + done, out.size() - done, off_t(offset + done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0)
      throw Error(p.path + ": cannot read at byte " + std::to_string(offset + done) +
                  (n < 0 ? std::string(": ") + std::strerror(errno) : std::string(": unexpected end of file")));
    done += size_t(n);
  }
}

std::unique_ptr<Part> open_part(const std::string& path) {
  auto p = std::make_unique<Part>();
  p->path = path;
  p->fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (p->fd < 0) throw Error(path + ": cannot open: " + std::strerror(errno));
  struct stat st{};
  if (::fstat(p->fd, &st) != 0) throw Error(path + ": stat: " + std::strerror(errno));
  p->size = uint64_t(st.st_size);
  std::array<uint8_t, kPackHeaderBytes> head{};
  if (p->size < kPackHeaderBytes) throw Error(path + ": not a part file (" + std::to_string(p->size) + " bytes)");
  pread_exact(*p, 0, head);
  p->header = PackHeader::parse(head, path);
  const PackHeader& h = p->header;
  if (h.state != PackState::building) throw Error(path + ": a complete pack, not a part file (build --shard I/N)");
  if (p->size < h.journal_offset) throw Error(path + ": truncated inside its build parameters");
  std::vector<uint8_t> blob(h.params_size);
  pread_exact(*p, h.params_offset, blob);
  if (crc32_of(blob) != h.params_crc) throw Error(path + ": build parameters fail their CRC");
  PackParamList list = parse_params(blob, path);
  auto it = std::find_if(list.begin(), list.end(), [](auto& kv) { return kv.first == kShardParam; });
  if (it == list.end()) throw Error(path + ": no shard parameter: a build's .tmp, not a part file (build --shard I/N)");
  p->shard = BuildShard::parse(it->second);
  list.erase(it);
  PackParams& pp = p->params;
  pp.light_kind = h.light_kind;
  pp.light = h.light;
  pp.map_level = h.map_level;
  pp.skip_level = h.skip_level;
  pp.encoding = h.encoding;
  pp.tile_bytes = h.tile_bytes;
  pp.scene_hash = h.scene_hash;
  pp.features = h.flags & uint32_t(kFeatureExitDepths | kFeatureDeepShadow | kFeatureStaticIntervals);
  pp.build_params = std::move(list);
  return p;
}

// The field in which two parts' maps or builds differ, or nullptr.
const char* difference(const Part& a, const Part& b) {
  const PackParams &x = a.params, &y = b.params;
  if (x.encoding != y.encoding) return "encoding";
  if (x.light_kind != y.light_kind || x.light != y.light) return "light";
  if (x.map_level != y.map_level) return "map level";
  if (x.skip_level != y.skip_level) return "skip level";
  if (x.tile_bytes != y.tile_bytes) return "tile_bytes";
  if (x.scene_hash != y.scene_hash) return "scene hash";
  if (x.features != y.features) return "features";
  if (x.build_params != y.build_params) return "build parameters";
  if (a.shard.count != b.shard.count) return "shard count";
  return nullptr;
}

MhConstruction construction_of(const PackParamList& params) {
  for (auto& [k, v] : params)
    if (k == "construction") return v == "top-down" ? MhConstruction::top_down : MhConstruction::bottom_up;
  return MhConstruction::bottom_up;
}

// Copies every part's cells into `writer` (checking each part holds exactly its shard's
// cells, intact), then finishes the pack.
MergeReport copy_and_finish(const std::vector<const Part*>& by_shard, const PackParams& pp, PackWriter& writer) {
  const uint32_t N = uint32_t(by_shard.size());
  MergeReport rep;
  rep.shard_count = N;
  std::vector<uint8_t> span;
  for (const Part* p : by_shard) {
    uint64_t cells = 0;
    std::string stray;
    const uint64_t end = replay_journal(
        p->fd, p->header.journal_offset, p->size, pp, p->path,
        [&](const CellRecord& c, std::vector<TileIndexEntry>&& tiles, uint64_t b, uint64_t e) {
          if (!p->shard.holds(c.cx, c.cy)) {
            stray = "cell (" + std::to_string(c.cx) + ", " + std::to_string(c.cy) + ")";
            return false;
          }
          span.resize(e - b);
          pread_exact(*p, b, span);
          writer.append_cell_bytes(span);  // checks every record again as it copies
          ++cells;
          rep.tiles += tiles.size();
          rep.bytes_copied += span.size();
          return true;
        });
    if (!stray.empty())
      throw Error("merge: " + p->path + " holds " + stray + ", which is not in its shard " + p->shard.to_string());
    if (end != p->size)
      throw Error("merge: " + p->path + ": record at byte " + std::to_string(end) +
                  " is torn or fails its CRC (rebuild this part with build --shard " + p->shard.to_string() +
                  " --resume)");
    const uint64_t want = p->shard.cell_count(pp.skip_level);
    if (cells != want)
      throw Error("merge: gap: " + p->path + " holds " + std::to_string(cells) + " of the " + std::to_string(want) +
                  " cells of shard " + p->shard.to_string() + " (finish it with build --shard " +
                  p->shard.to_string() + " --resume)");
    rep.cells += cells;
  }
  CutParams cut;
  cut.map_level = pp.map_level;
  cut.skip_level = pp.skip_level;
  cut.tile_bytes = pp.tile_bytes;
  cut.codec = TileCodec::of(pp.encoding);
  TileCutter cutter(cut);
  const MhConstruction method = construction_of(pp.build_params);
  writer.finish(
      cutter.coarse_grid(writer.cells(), [method](const IntervalTile& t) { return build_hierarchy(t, method); }));
  return rep;
}

}  // namespace

MergeReport merge_parts(std::span<const std::string> part_paths, const std::string& out_path, bool dagmh_dictionary) {
  if (part_paths.empty()) throw Error("merge: no part files given");
  std::vector<std::unique_ptr<Part>> parts;
  for (const std::string& path : part_paths) parts.push_back(open_part(path));
  const Part& first = *parts.front();
  const uint32_t N = first.shard.count;
  std::vector<const Part*> by_shard(N, nullptr);
  for (auto& p : parts) {
    if (const char* field = difference(first, *p))
      throw Error("merge: " + p->path + " and " + first.path + " are parts of different builds (" + field +
                  " differs)");
    const Part*& slot = by_shard[p->shard.index];
    if (slot)
      throw Error("merge: overlap: " + slot->path + " and " + p->path + " both hold shard " + p->shard.to_string());
    slot = p.get();
  }
  std::string missing;
  uint32_t n_missing = 0;
  for (uint32_t i = 0; i < N; ++i)
    if (!by_shard[i] && n_missing++ < 8) missing += (missing.empty() ? "" : ", ") + BuildShard{i, N}.to_string();
  if (n_missing)
    throw Error("merge: gap: no part holds shard" + std::string(n_missing > 1 ? "s " : " ") + missing +
                (n_missing > 8 ? " (and " + std::to_string(n_missing - 8) + " more)" : "") + " of " +
                std::to_string(N));

  PackParams pp = first.params;
  pp.dagmh_dictionary = dagmh_dictionary && pp.encoding == Encoding::dagmh;
  auto writer = PackWriter::create(out_path, pp);
  try {
    MergeReport rep = copy_and_finish(by_shard, pp, *writer);
    rep.dictionary_bytes = writer->dictionary_outcome().bytes;
    return rep;
  } catch (...) {
    ::unlink(writer->tmp_path().c_str());  // a refused merge leaves nothing behind
    throw;
  }
}

}  // namespace st
