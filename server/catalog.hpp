// The server's catalog: the packs it serves, by map name. Built once at start from files
// and directories given on the command line; a client can only name a catalog entry
// (proto map-name rules: no '/', no leading '.'), never a path.
//
// A map's name is its file name (the last path component) without a final ".pack"
// extension; a file named on the command line without that extension keeps its whole file
// name. Directories contribute their regular "*.pack" files (not recursively; "*.pack.tmp"
// builds in progress are skipped), and a file there whose name breaks the map-name rules
// is skipped with a warning. Names are case-sensitive; the catalog lists them sorted by
// byte value.
// Every pack is opened and validated up front (header, skip grid, tile index), so a
// corrupt pack stops the server at start, not at the first request.
//
// Thread safety: immutable after construction; read() uses pread, so any number of
// threads may read tiles concurrently.
#pragma once
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "proto/messages.hpp"
#include "tiles/core/pack_reader.hpp"

namespace st::server {

class CatalogMap {
 public:
  CatalogMap(std::string name, std::string path);  // opens and validates; st::Error
  const std::string& name() const { return name_; }
  const std::string& path() const { return path_; }
  const PackReader& pack() const { return *pack_; }
  const proto::MapEntry& entry() const { return entry_; }
  // The largest stored (zlib) tile of the pack (0: none): its TileData frame needs this
  // + 52 bytes (PROTOCOL.md §6).
  uint32_t largest_stored_tile() const { return largest_stored_tile_; }
  // The MapInfo frame answering OpenMap: header, map id, pack header and skip grid.
  uint64_t map_info_frame_bytes() const;
  // The MapInfo payload after its map id (PROTOCOL.md §4.6: pack header and skip grid,
  // each behind its u32 length), built once and shared by every answer on every
  // connection: pipelined OpenMaps queue references to it, never copies.
  const std::shared_ptr<const std::vector<uint8_t>>& map_info_tail() const { return map_info_tail_; }
  // The MapInfo payload's CRC-32 for `map_id` (4 id bytes, then the tail), computed once
  // per id (ids are 1..max_open_maps) so an OpenMap costs no pass over a big skip grid.
  uint32_t map_info_crc(uint32_t map_id) const;

 private:
  std::string name_, path_;
  std::unique_ptr<PackReader> pack_;
  proto::MapEntry entry_;
  uint32_t largest_stored_tile_ = 0;
  std::shared_ptr<const std::vector<uint8_t>> map_info_tail_;
  mutable std::mutex crc_mu_;
  mutable std::map<uint32_t, uint32_t> crc_by_id_;
};

class Catalog {
 public:
  Catalog() = default;
  // Files and directories; throws st::Error for a missing path, a named file that is not
  // a valid pack or map name, a duplicate name, or an empty catalog. `warn` receives one
  // line per skipped file in a directory (invalid name or pack).
  static Catalog scan(std::span<const std::string> paths,
                      const std::function<void(const std::string&)>& warn = {});
  void add(std::string name, std::string path);  // st::Error on a duplicate or bad name

  const CatalogMap* find(std::string_view name) const;
  // The map's position in maps() (its index in the server's payload cache); npos if none.
  static constexpr size_t npos = size_t(-1);
  size_t index_of(std::string_view name) const;
  const std::vector<std::shared_ptr<const CatalogMap>>& maps() const { return maps_; }

 private:
  std::vector<std::shared_ptr<const CatalogMap>> maps_;  // sorted by name
};

}  // namespace st::server
