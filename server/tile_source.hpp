// Where a connection gets a tile's stored bytes (what it sends behind the TileData fields).
// The server's own source is PackTileSource: pread from the map's pack and the pack index's
// CRC check (PackReader::read_stored). A caller may give the server another one
// (ServerOptions::tile_source), for example one that wraps PackTileSource to model a slow
// or failing disk; the server then trusts nothing about its bytes (below).
#pragma once
#include <cstdint>
#include <vector>

#include "tiles/core/pack_reader.hpp"

namespace st::server {

class TileSource {
 public:
  virtual ~TileSource() = default;
  // The stored bytes of tile `tile_id` of `pack`. Throws st::Error when they cannot be
  // read or fail a check: that tile is answered with a TileError, the rest are served.
  // Called from the I/O threads at once: implementations are thread-safe.
  virtual std::vector<uint8_t> read(const PackReader& pack, uint64_t tile_id) = 0;
  // True when read() answers exactly the bytes the pack index's CRC covers, checked against
  // it. Only then does the server keep them in its payload cache and combine the frame's
  // CRC from the index's; otherwise every tile is read and summed as it is sent.
  virtual bool answers_checked_pack_bytes() const { return false; }
};

// The pack itself (the default source).
class PackTileSource final : public TileSource {
 public:
  std::vector<uint8_t> read(const PackReader& pack, uint64_t tile_id) override { return pack.read_stored(tile_id); }
  bool answers_checked_pack_bytes() const override { return true; }
};

}  // namespace st::server
