// The public API (shadowtile/client.hpp) over the fetcher and the opened maps. This is
// the library boundary: internal errors surface as std::runtime_error (st::Error derives
// from it) only where the header says so.
#include "shadowtile/client.hpp"

#include <algorithm>
#include <atomic>

#include "client/call_error.hpp"
#include "client/fetcher.hpp"
#include "client/map_access.hpp"
#include "client/remote_map.hpp"
#include "common/error.hpp"
#include "tiles/core/encoding.hpp"
#include "tiles/core/interval.hpp"

namespace st::client {

// ---------------------------------------------------------------- Map

const RemoteMap& MapAccess::remote(const Map& m) {
  if (!m.map_) throw Error("client: this Map was default-constructed (no map opened)");
  return *m.map_;
}

MapInfo Map::info() const {
  MapInfo i;
  if (!map_) return i;
  const PackHeader& h = map_->header();
  i.name = map_->name();
  i.encoding = to_string(h.encoding);
  i.finest_level = h.map_level;
  i.skip_level = h.skip_level;
  i.tile_bytes = h.tile_bytes;
  i.tile_count = h.tile_count;
  i.scene_hash = h.scene_hash;
  i.sun = h.light_kind == LightKind::sun || h.light_kind == LightKind::sun_ground;
  i.light.space_ = map_->info_light();
  const SurfaceExtent& e = map_->surface();
  i.scene.bounds = {{e.box.lo.x, e.box.lo.y, e.box.lo.z}, {e.box.hi.x, e.box.hi.y, e.box.hi.z}};
  i.scene.ground = e.ground, i.scene.top = e.top;
  i.scene.x0 = e.x0, i.scene.x1 = e.x1, i.scene.z0 = e.z0, i.scene.z1 = e.z1;
  i.scene.points = e.points;
  if (const StackGrid* g = map_->stack_grid())
    for (uint32_t w = 0; w < g->slices; ++w) {
      LightTransform t;
      t.space_ = std::make_shared<const LightSpace>(g->light(w));
      i.slice_lights.push_back(std::move(t));
    }
  return i;
}

ViewStats Map::request_view(uint32_t view_id, const double view_projection[16], uint32_t width, uint32_t height,
                            const ViewOptions& options) noexcept {
  return map_ ? map_->request_view(view_id, view_projection, width, height, options) : ViewStats{};
}
bool Map::remove_view(uint32_t view_id) noexcept { return map_ && map_->remove_view(view_id); }
ViewStats Map::view_stats(uint32_t view_id) const noexcept { return map_ ? map_->view_stats(view_id) : ViewStats{}; }
size_t Map::view_samples(const double view_projection[16], uint32_t width, uint32_t height, const ViewOptions& options,
                         std::span<ViewSample> out) const noexcept {
  return map_ ? map_->view_samples(view_projection, width, height, options, out) : 0;
}

// ---------------------------------------------------------------- LightTransform

namespace {
WorldPoint wp(const Vec3d& v) { return {v.x, v.y, v.z}; }
Vec3d v3(const WorldPoint& p) { return {p.x, p.y, p.z}; }
}  // namespace

bool LightTransform::orthographic() const noexcept { return space_ && space_->parallel(); }
const char* LightTransform::kind_name() const noexcept { return space_ ? light_kind_name(space_->kind()) : ""; }
WorldPoint LightTransform::origin() const noexcept { return space_ ? wp(space_->origin()) : WorldPoint{}; }
WorldPoint LightTransform::axis_u() const noexcept { return space_ ? wp(space_->axis_u()) : WorldPoint{}; }
WorldPoint LightTransform::axis_v() const noexcept { return space_ ? wp(space_->axis_v()) : WorldPoint{}; }
WorldPoint LightTransform::forward() const noexcept { return space_ ? wp(space_->forward()) : WorldPoint{}; }
double LightTransform::extent() const noexcept { return space_ ? space_->extent_uv() : 0; }
double LightTransform::near_plane() const noexcept { return space_ ? space_->near_plane() : 0; }
double LightTransform::far_plane() const noexcept { return space_ ? space_->far_plane() : 0; }

LightCoord LightTransform::to_light(const WorldPoint& p) const noexcept {
  if (!space_) return {};
  const LightPoint l = space_->to_light(v3(p));
  return {l.u, l.v, l.d};
}
Texel LightTransform::texel(uint32_t level, const LightCoord& c) const noexcept {
  if (!space_) return {};
  const auto t = LightSpace::texel_of(std::min<uint32_t>(level, 30), c.u, c.v);
  return {t[0], t[1]};
}
Texel LightTransform::texel(uint32_t level, const WorldPoint& p) const noexcept { return texel(level, to_light(p)); }
double LightTransform::texel_size(const WorldPoint& p, uint32_t level) const noexcept {
  return space_ ? space_->texel_size(v3(p), level) : 0;
}
WorldPoint LightTransform::to_world(const LightCoord& c) const noexcept {
  return space_ ? wp(space_->to_world(c.u, c.v, c.d)) : WorldPoint{};
}
uint8_t LightTransform::kind_id() const noexcept { return space_ ? uint8_t(space_->kind()) : 0; }
std::array<double, 18> LightTransform::to_array() const noexcept {
  return space_ ? space_->to_array() : std::array<double, 18>{};
}
WorldBox LightTransform::volume_bounds() const noexcept {
  if (!space_) return {};
  Aabb b;
  for (int i = 0; i < 8; ++i) b.extend(space_->to_world(i & 1, (i >> 1) & 1, (i >> 2) & 1));
  return {wp(b.lo), wp(b.hi)};
}

uint32_t Map::finest_level() const noexcept { return map_ ? map_->finest_level() : 0; }

float Map::depth(uint32_t level, uint64_t x, uint64_t y) const noexcept {
  return map_ ? map_->depth(level, x, y) : kLitDepth;
}
// The one PCF unit of the public API is the kernel side (client.hpp "PCF"); the
// internal lookups below take a radius (side = 2 * radius + 1). An invalid side answers NaN.
namespace {
constexpr float kBadSide = std::numeric_limits<float>::quiet_NaN();
constexpr uint32_t radius_of(uint32_t side) noexcept { return (side - 1) / 2; }
// Fills out[0, n) with NaN (a batch given an invalid side); returns true when it did.
bool refuse_side(uint32_t side, std::span<float> out, size_t n) noexcept {
  if (pcf_side_valid(side)) return false;
  std::fill_n(out.begin(), std::min(n, out.size()), kBadSide);
  return true;
}
}  // namespace

float Map::pcf(uint32_t level, uint64_t x, uint64_t y, uint32_t side, float receiver) const noexcept {
  if (!pcf_side_valid(side)) return kBadSide;
  return map_ ? map_->pcf(level, x, y, side, receiver) : 1.0f;
}
bool Map::lit(uint64_t x, uint64_t y, float receiver_depth) const noexcept {
  return receiver_depth <= depth(finest_level(), x, y);
}
float Map::visibility(const WorldPoint& world, uint32_t pcf_side) const noexcept {
  if (!pcf_side_valid(pcf_side)) return kBadSide;
  return map_ ? map_->visibility(Vec3d{world.x, world.y, world.z}, radius_of(pcf_side)) : 1.0f;
}
float Map::visibility_filtered(const WorldPoint& world, float footprint, uint32_t pcf_side) const noexcept {
  if (!pcf_side_valid(pcf_side)) return kBadSide;
  float out = 1.0f;
  if (map_) map_->visibility_batch({&world, 1}, {&footprint, 1}, {&out, 1}, radius_of(pcf_side));
  return out;
}
void Map::visibility(std::span<const WorldPoint> points, std::span<float> out, uint32_t pcf_side) const noexcept {
  if (refuse_side(pcf_side, out, points.size())) return;
  if (map_) map_->visibility_batch(points, {}, out, radius_of(pcf_side));
  else std::fill_n(out.begin(), std::min(points.size(), out.size()), 1.0f);
}
void Map::visibility_filtered(std::span<const WorldPoint> points, std::span<const float> footprints,
                              std::span<float> out, uint32_t pcf_side) const noexcept {
  if (footprints.empty()) return;  // nothing to answer: the smallest span is empty
  if (refuse_side(pcf_side, out, std::min(points.size(), footprints.size()))) return;
  if (map_) map_->visibility_batch(points, footprints, out, radius_of(pcf_side));
  else std::fill_n(out.begin(), std::min({points.size(), footprints.size(), out.size()}), 1.0f);
}
float Map::visibility_filtered(const WorldPoint& world, const WorldPoint& normal, float footprint, uint32_t pcf_side,
                              bool closed) const noexcept {
  if (!pcf_side_valid(pcf_side)) return kBadSide;
  float out = 1.0f;
  if (map_) map_->visibility_plane_batch({&world, 1}, {&normal, 1}, {&footprint, 1}, {&out, 1}, radius_of(pcf_side), closed);
  return out;
}
void Map::visibility_filtered(std::span<const WorldPoint> points, std::span<const WorldPoint> normals,
                              std::span<const float> footprints, std::span<float> out, uint32_t pcf_side,
                              bool closed) const noexcept {
  const size_t n = std::min({points.size(), normals.size(), footprints.size()});
  if (n == 0) return;  // nothing to answer: the smallest span is empty
  if (refuse_side(pcf_side, out, n)) return;
  if (map_) map_->visibility_plane_batch(points, normals, footprints, out, radius_of(pcf_side), closed);
  else std::fill_n(out.begin(), std::min(n, out.size()), 1.0f);
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
uint32_t Map::slices() const noexcept {
  return map_ && map_->stack_grid() ? map_->stack_grid()->slices : 0;
}
float Map::time_visibility(const WorldPoint& world, double time, uint32_t pcf_side) const noexcept {
  if (!pcf_side_valid(pcf_side)) return kBadSide;
  return map_ ? map_->stack_visibility({world.x, world.y, world.z}, time, radius_of(pcf_side)) : 1.0f;
}
float Map::time_visibility_filtered(const WorldPoint& world, double time, float footprint,
                                    uint32_t pcf_side) const noexcept {
  if (!pcf_side_valid(pcf_side)) return kBadSide;
  return map_ ? map_->stack_visibility({world.x, world.y, world.z}, time, radius_of(pcf_side), footprint) : 1.0f;
}
float Map::soft_visibility(const WorldPoint& world, uint32_t pcf_side) const noexcept {
  if (!pcf_side_valid(pcf_side)) return kBadSide;
  return map_ ? map_->stack_soft_visibility({world.x, world.y, world.z}, radius_of(pcf_side)) : 1.0f;
}
void Map::soft_visibility(std::span<const WorldPoint> points, std::span<float> out, uint32_t pcf_side) const noexcept {
  if (refuse_side(pcf_side, out, points.size())) return;
  if (map_) map_->stack_soft_visibility_batch(points, out, radius_of(pcf_side));
  else std::fill_n(out.begin(), std::min(points.size(), out.size()), 1.0f);
}
float Map::soft_visibility_filtered(const WorldPoint& world, float footprint, uint32_t pcf_side) const noexcept {
  if (!pcf_side_valid(pcf_side)) return kBadSide;
  return map_ ? map_->stack_soft_visibility({world.x, world.y, world.z}, radius_of(pcf_side), footprint) : 1.0f;
}
float Map::time_visibility_filtered(const WorldPoint& world, const WorldPoint& normal, double time, float footprint,
                                    uint32_t pcf_side, bool closed) const noexcept {
  if (!pcf_side_valid(pcf_side)) return kBadSide;
  return map_ ? map_->stack_visibility_plane({world.x, world.y, world.z}, {normal.x, normal.y, normal.z}, time,
                                             radius_of(pcf_side), footprint, closed)
              : 1.0f;
}
float Map::soft_visibility_filtered(const WorldPoint& world, const WorldPoint& normal, float footprint,
                                    uint32_t pcf_side, bool closed) const noexcept {
  if (!pcf_side_valid(pcf_side)) return kBadSide;
  return map_ ? map_->stack_soft_visibility_plane({world.x, world.y, world.z}, {normal.x, normal.y, normal.z},
                                                  radius_of(pcf_side), footprint, closed)
              : 1.0f;
}
float Map::slice_depth(uint32_t slice, uint32_t level, uint64_t x, uint64_t y) const noexcept {
  return map_ ? map_->stack_depth(slice, level, x, y) : 1.0f;
}
size_t Map::request_slices(uint32_t w0, uint32_t w1, uint16_t priority) noexcept {
  return map_ ? map_->request_slices(w0, w1, priority) : 0;
}
bool Map::slices_resident(uint32_t w0, uint32_t w1) const noexcept {
  return map_ ? map_->slices_resident(w0, w1) : true;
}
bool Map::has_deep() const noexcept { return map_ && map_->deep(); }
Transmittance Map::transmittance(const WorldPoint& world) const noexcept { return transmittance_filtered(world, 0); }
Transmittance Map::transmittance_filtered(const WorldPoint& world, float footprint) const noexcept {
  if (!map_ || !map_->deep()) return {};
  const LightSpace& l = map_->light();
  const Vec3d w{world.x, world.y, world.z};
  const LightPoint p = l.to_light(w);
  // The footprint in map units: world units over the light's image-plane extent there (a
  // spot's grows with the distance from the eye), as visibility_filtered.
  double width = 0;
  if (footprint > 0)
    width = double(footprint) / l.texel_size(w, 0);
  const auto t = map_->deep()->lookup(p.u, p.v, float(p.d), width);
  return {t[0], t[1], t[2]};
}
bool Map::deep_resident(double u0, double v0, double u1, double v1) const noexcept {
  return map_ && map_->deep() && map_->deep()->resident(u0, v0, u1, v1);
}
uint32_t Map::deep_level() const noexcept { return map_ && map_->deep() ? map_->deep()->level() : 0; }
Transmittance Map::transmittance_at(const LightCoord& c, double footprint_uv) const noexcept {
  if (!map_ || !map_->deep()) return {};
  const std::array<float, 3> t = map_->deep()->lookup(c.u, c.v, float(c.d), footprint_uv);
  return {t[0], t[1], t[2]};
}
MapStats Map::stats() const noexcept { return map_ ? map_->stats() : MapStats{}; }
uint32_t Map::slot_bytes() const noexcept { return map_ ? map_->slot_bytes() : 0; }

// ---------------------------------------------------------------- ServerStats

uint64_t ServerStats::counter(const std::string& name) const noexcept {
  for (const Counter& c : counters)
    if (c.name == name) return c.value;
  return 0;
}

// ---------------------------------------------------------------- Client

Client::Client(Endpoint endpoint, ClientOptions options)
    : fetcher_(std::make_shared<Fetcher>(std::vector<Endpoint>{std::move(endpoint)}, 0, std::move(options))) {
  fetcher_->start();
}

namespace {
// Clients of one process start at successive replicas: their connections spread evenly.
std::atomic<size_t> g_next_replica{0};
}  // namespace

Client::Client(std::vector<Endpoint> endpoints, ClientOptions options)
    : fetcher_(std::make_shared<Fetcher>(std::move(endpoints), g_next_replica.fetch_add(1), std::move(options))) {
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

std::vector<MapListing> Client::list_maps() {
  proto::Message m = fetcher_->call(proto::ListMaps{});
  auto* list = std::get_if<proto::MapList>(&m);
  if (!list) throw CallError(CallFailure::unexpected_answer, "client: list_maps: unexpected answer");
  std::vector<MapListing> out;
  out.reserve(list->maps.size());
  for (const proto::MapEntry& e : list->maps) {
    MapListing l;
    l.name = e.name;
    l.encoding = to_string(Encoding(e.encoding));  // names unknown tags "encoding#N"
    l.resolution_log2 = e.resolution_log2;
    l.skip_level = e.skip_level;
    l.tile_count = e.tile_count;
    l.pack_bytes = e.pack_bytes;
    out.push_back(std::move(l));
  }
  return out;
}

ServerStats Client::server_stats() {
  proto::Message m = fetcher_->call(proto::GetStats{});
  auto* s = std::get_if<proto::Stats>(&m);
  if (!s) throw CallError(CallFailure::unexpected_answer, "client: server_stats: unexpected answer");
  ServerStats out;
  for (const proto::Counter& c : s->counters) out.counters.push_back({c.name, c.value});
  for (const proto::Histogram& h : s->histograms) {
    ServerStats::Histogram oh{h.name, {}};
    for (const proto::Bucket& b : h.buckets) oh.buckets.push_back({b.upper_bound, b.count});
    out.histograms.push_back(std::move(oh));
  }
  return out;
}

bool Client::connected() const noexcept { return fetcher_->connected(); }
ClientStats Client::stats() const noexcept { return fetcher_->stats(); }

}  // namespace st::client
