#include "server/catalog.hpp"

#include <algorithm>
#include <filesystem>

#include "proto/frame.hpp"
#include "proto/names.hpp"
#include "common/error.hpp"

namespace st::server {
namespace fs = std::filesystem;

namespace {
constexpr std::string_view kPackExt = ".pack";

bool ends_with(std::string_view s, std::string_view suffix) {
  return s.size() >= suffix.size() && s.substr(s.size() - suffix.size()) == suffix;
}
}  // namespace

CatalogMap::CatalogMap(std::string name, std::string path)
    : name_(std::move(name)), path_(std::move(path)) {
  if (proto::Status s = proto::validate_map_name(name_); !s)
    throw Error("serve: " + path_ + ": '" + name_ + "' is not a valid map name (" +
                proto::to_string(s) + ")");
  pack_ = PackReader::open(path_);  // validates header, skip grid and index; st::FormatError
  const PackHeader& h = pack_->header();
  entry_.name = name_;
  entry_.encoding = uint8_t(h.encoding);
  entry_.resolution_log2 = uint8_t(h.map_level);
  entry_.skip_level = uint8_t(h.skip_level);
  if (h.tile_count > UINT32_MAX) throw Error("serve: " + path_ + ": too many tiles");
  entry_.tile_count = uint32_t(h.tile_count);
  entry_.pack_bytes = pack_->file_size();
  for (const TileIndexEntry& t : pack_->tiles()) largest_stored_tile_ = std::max(largest_stored_tile_, t.stored_size);
  auto tail = std::make_shared<std::vector<uint8_t>>();
  auto put = [&](std::span<const uint8_t> b) {
    const uint32_t n = uint32_t(b.size());
    for (int i = 0; i < 4; ++i) tail->push_back(uint8_t(n >> (8 * i)));  // little endian (§3)
    tail->insert(tail->end(), b.begin(), b.end());
  };
  // MapInfo's header carries tile_bytes tightened to the largest tile the pack holds (raw,
  // index and deep tiles included, rounded up to 64 bytes): a client sizes its cache slots by that bound, and a
  // build's target (64 KiB by default) over tiles of 1 KB would give it 60x fewer slots
  // than its memory holds. Only when the header re-serializes to the file's bytes (a
  // header this reader fully understands); the file itself is untouched.
  std::vector<uint8_t> header(pack_->header_bytes().begin(), pack_->header_bytes().end());
  uint32_t largest_raw = 0;
  for (const TileIndexEntry& t : pack_->tiles()) largest_raw = std::max(largest_raw, t.raw_size);
  // Rounded up to 64 bytes: slots (and the tiles in them) stay aligned to cache lines.
  const uint32_t bound = std::min(h.tile_bytes, uint32_t((uint64_t(largest_raw) + 63) & ~uint64_t(63)));
  if (largest_raw > 0 && bound < h.tile_bytes) {
    const auto same = h.serialize();
    if (std::equal(same.begin(), same.end(), header.begin(), header.end())) {
      PackHeader tight = h;
      tight.tile_bytes = bound;
      const auto b = tight.serialize();
      header.assign(b.begin(), b.end());
    }
  }
  put(header);
  put(pack_->grid_bytes());
  map_info_tail_ = std::move(tail);
}

uint32_t CatalogMap::map_info_crc(uint32_t map_id) const {
  std::lock_guard lock(crc_mu_);
  if (auto it = crc_by_id_.find(map_id); it != crc_by_id_.end()) return it->second;
  const uint8_t id[4] = {uint8_t(map_id), uint8_t(map_id >> 8), uint8_t(map_id >> 16), uint8_t(map_id >> 24)};
  const uint32_t crc = proto::crc32(*map_info_tail_, proto::crc32(id));
  crc_by_id_.emplace(map_id, crc);
  return crc;
}

uint64_t CatalogMap::map_info_frame_bytes() const {
  return proto::kHeaderSize + 12 + pack_->header_bytes().size() + pack_->grid_bytes().size();
}

void Catalog::add(std::string name, std::string path) {
  if (find(name)) throw Error("serve: two packs named '" + name + "' (" + path + ")");
  auto map = std::make_shared<const CatalogMap>(std::move(name), std::move(path));
  auto at = std::lower_bound(maps_.begin(), maps_.end(), map->name(),
                             [](const auto& m, const std::string& n) { return m->name() < n; });
  maps_.insert(at, std::move(map));
}

const CatalogMap* Catalog::find(std::string_view name) const {
  const size_t i = index_of(name);
  return i == npos ? nullptr : maps_[i].get();
}

size_t Catalog::index_of(std::string_view name) const {
  auto at = std::lower_bound(maps_.begin(), maps_.end(), name,
                             [](const auto& m, std::string_view n) { return m->name() < n; });
  return at != maps_.end() && (*at)->name() == name ? size_t(at - maps_.begin()) : npos;
}

Catalog Catalog::scan(std::span<const std::string> paths,
                      const std::function<void(const std::string&)>& warn) {
  Catalog c;
  for (const std::string& p : paths) {
    std::error_code ec;
    auto status = fs::status(p, ec);
    if (ec || !fs::exists(status)) throw Error("serve: " + p + ": no such file or directory");
    if (fs::is_directory(status)) {
      std::vector<fs::path> files;
      for (const auto& e : fs::directory_iterator(p, ec))
        if (e.is_regular_file() && ends_with(e.path().filename().string(), kPackExt))
          files.push_back(e.path());
      if (ec) throw Error("serve: " + p + ": " + ec.message());
      std::sort(files.begin(), files.end());
      for (const auto& f : files) {
        std::string name = f.filename().string();
        name.resize(name.size() - kPackExt.size());
        try {
          c.add(name, f.string());
        } catch (const Error& e) {
          if (warn) warn(std::string("skipping ") + f.string() + ": " + e.what());
        }
      }
    } else {
      std::string name = fs::path(p).filename().string();
      if (ends_with(name, kPackExt)) name.resize(name.size() - kPackExt.size());
      c.add(name, p);
    }
  }
  if (c.maps_.empty()) throw Error("serve: no packs to serve in the given paths");
  return c;
}

}  // namespace st::server
