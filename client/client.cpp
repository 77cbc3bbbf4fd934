#include "client/client.hpp"

#include "client/fetcher.hpp"
#include "client/remote_map.hpp"
#include "common/error.hpp"
#include "tiles/core/interval.hpp"

namespace st::client {

// ---------------------------------------------------------------- Map

namespace {
const std::string kNoName;
const PackHeader kNoHeader{};
const CutGrid kNoGrid{};
}  // namespace

const std::string& Map::name() const noexcept { return map_ ? map_->name() : kNoName; }
const PackHeader& Map::header() const noexcept { return map_ ? map_->header() : kNoHeader; }
const CutGrid& Map::skip_grid() const noexcept { return map_ ? map_->grid() : kNoGrid; }
uint32_t Map::finest_level() const noexcept { return map_ ? map_->finest_level() : 0; }
const Evaluator& Map::evaluator() const noexcept { return *map_; }

float Map::depth(uint32_t level, uint64_t x, uint64_t y) const noexcept {
  return map_ ? map_->depth(level, x, y) : kLitDepth;
}
float Map::pcf(uint32_t level, uint64_t x, uint64_t y, uint32_t r, float receiver) const noexcept {
  return map_ ? map_->pcf(level, x, y, r, receiver) : 1.0f;
}
bool Map::lit(uint64_t x, uint64_t y, float receiver_depth) const noexcept {
  return receiver_depth <= depth(finest_level(), x, y);
}
float Map::visibility(const Vec3d& world, uint32_t pcf_radius) const noexcept {
  return map_ ? map_->visibility(world, pcf_radius) : 1.0f;
}
size_t Map::request_region(uint32_t level, uint64_t x0, uint64_t y0, uint64_t w, uint64_t h,
                           uint16_t priority) noexcept {
  return map_ ? map_->request_region(level, x0, y0, w, h, priority) : 0;
}
size_t Map::cancel_outside(uint32_t level, uint64_t x0, uint64_t y0, uint64_t w, uint64_t h) noexcept {
  return map_ ? map_->cancel_outside(level, x0, y0, w, h) : 0;
}
bool Map::region_resident(uint32_t level, uint64_t x0, uint64_t y0, uint64_t w, uint64_t h) const noexcept {
  return map_ ? map_->region_resident(level, x0, y0, w, h) : false;
}
MapStats Map::stats() const noexcept { return map_ ? map_->stats() : MapStats{}; }
uint32_t Map::slot_bytes() const noexcept { return map_ ? map_->slot_bytes() : 0; }

// ---------------------------------------------------------------- Client

Client::Client(Endpoint endpoint, ClientOptions options)
    : fetcher_(std::make_shared<Fetcher>(std::move(endpoint), std::move(options))) {
  fetcher_->start();
}

Client::~Client() { fetcher_->stop(); }

Map Client::open(const std::string& name) {
  try {
    return Map(fetcher_->open(name));
  } catch (const Error&) {
    throw;
  } catch (const std::exception& e) {  // bad_alloc and the like, as st::Error
    throw Error("client: open('" + name + "'): " + e.what());
  }
}

std::vector<proto::MapEntry> Client::list_maps() {
  proto::Message m = fetcher_->call(proto::ListMaps{});
  auto* list = std::get_if<proto::MapList>(&m);
  if (!list) throw Error("client: list_maps: unexpected answer");
  return std::move(list->maps);
}

proto::Stats Client::server_stats() {
  proto::Message m = fetcher_->call(proto::GetStats{});
  auto* s = std::get_if<proto::Stats>(&m);
  if (!s) throw Error("client: server_stats: unexpected answer");
  return std::move(*s);
}

bool Client::connected() const noexcept { return fetcher_->connected(); }
ClientStats Client::stats() const noexcept { return fetcher_->stats(); }

}  // namespace st::client
