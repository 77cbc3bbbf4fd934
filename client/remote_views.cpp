// Cameras: Map::request_view (client.hpp). A view is a set of tiles, recomputed from the
// camera on every request:
//   1. (views_mu_, lock shared) each screen sample's ray (Rays: the one loop, also behind
//      Map::view_samples) meets the receiver plane at p; its pixel's footprint there is
//      t * pixel_angle (a perspective camera; an orthographic one's is constant); the
//      level is filter_levels' fine level for that footprint (what visibility_filtered
//      reads), and levels <= K + p need nothing (the skip grid and the map preview answer
//      them exactly). The page-table walk at p's texel of that level names the tile
//      needed (through resident index tiles, which are kept too). With the frame's time
//      (ViewOptions::time) and the previous request's matrix and time, the matrix is
//      extrapolated to poses ahead (ahead_times: one frame interval, then doubling up to
//      ViewOptions::lookahead) and their samples' tiles are added, flagged `ahead`.
//   2. The tiles, deduplicated (a need now over a need ahead, nearest distance kept), are
//      ordered nearest first, the poses ahead after, and cut to the view's share of
//      view_slots(): views of higher priority claim their tiles first, so a near camera is
//      never starved by a minimap or a prefetch, and a view's own tiles before its poses
//      ahead.
//   3. (lock exclusive) the tiles that left this view and are in no other have their
//      fetches cancelled (queued: dropped; sent: Cancel); the kept ones are wanted at
//      priority options.priority - rank; a tile seen resident before, still in the
//      view and now absent is counted as a refetch (MapStats::view_refetches). Tiles
//      ahead are held like the view's own but are not counted as its needs
//      (ViewStats::ahead).
// The slots of the views' tiles are flagged (slot_in_view_: set when a view takes a
// resident tile or a tile of a view arrives, cleared when it leaves every view), and
// before every eviction sync_lru_locked makes them the most recently used (one pass over
// the slots, which it makes anyway), so while the views' tiles fit in view_slots() the
// tile evicted is one no view holds (the rest of the slots: arrivals being filled and the
// lookups' own misses).
#include <algorithm>
#include <cmath>

#include "client/remote_map.hpp"
#include "tiles/core/filter_level.hpp"

namespace st::client {

namespace {

using Mat4 = std::array<double, 16>;  // column-major: element (r, c) at [c * 4 + r]

// The inverse of m (column-major); false when m is singular or not finite.
bool invert(const double* m, Mat4& out) {
  // Cofactor expansion (the MESA gluInvertMatrix arrangement), in double.
  Mat4 inv;
  inv[0] = m[5] * m[10] * m[15] - m[5] * m[11] * m[14] - m[9] * m[6] * m[15] + m[9] * m[7] * m[14] +
           m[13] * m[6] * m[11] - m[13] * m[7] * m[10];
  inv[4] = -m[4] * m[10] * m[15] + m[4] * m[11] * m[14] + m[8] * m[6] * m[15] - m[8] * m[7] * m[14] -
           m[12] * m[6] * m[11] + m[12] * m[7] * m[10];
  inv[8] = m[4] * m[9] * m[15] - m[4] * m[11] * m[13] - m[8] * m[5] * m[15] + m[8] * m[7] * m[13] +
           m[12] * m[5] * m[11] - m[12] * m[7] * m[9];
  inv[12] = -m[4] * m[9] * m[14] + m[4] * m[10] * m[13] + m[8] * m[5] * m[14] - m[8] * m[6] * m[13] -
            m[12] * m[5] * m[10] + m[12] * m[6] * m[9];
  inv[1] = -m[1] * m[10] * m[15] + m[1] * m[11] * m[14] + m[9] * m[2] * m[15] - m[9] * m[3] * m[14] -
           m[13] * m[2] * m[11] + m[13] * m[3] * m[10];
  inv[5] = m[0] * m[10] * m[15] - m[0] * m[11] * m[14] - m[8] * m[2] * m[15] + m[8] * m[3] * m[14] +
           m[12] * m[2] * m[11] - m[12] * m[3] * m[10];
  inv[9] = -m[0] * m[9] * m[15] + m[0] * m[11] * m[13] + m[8] * m[1] * m[15] - m[8] * m[3] * m[13] -
           m[12] * m[1] * m[11] + m[12] * m[3] * m[9];
  inv[13] = m[0] * m[9] * m[14] - m[0] * m[10] * m[13] - m[8] * m[1] * m[14] + m[8] * m[2] * m[13] +
            m[12] * m[1] * m[10] - m[12] * m[2] * m[9];
  inv[2] = m[1] * m[6] * m[15] - m[1] * m[7] * m[14] - m[5] * m[2] * m[15] + m[5] * m[3] * m[14] +
           m[13] * m[2] * m[7] - m[13] * m[3] * m[6];
  inv[6] = -m[0] * m[6] * m[15] + m[0] * m[7] * m[14] + m[4] * m[2] * m[15] - m[4] * m[3] * m[14] -
           m[12] * m[2] * m[7] + m[12] * m[3] * m[6];
  inv[10] = m[0] * m[5] * m[15] - m[0] * m[7] * m[13] - m[4] * m[1] * m[15] + m[4] * m[3] * m[13] +
            m[12] * m[1] * m[7] - m[12] * m[3] * m[5];
  inv[14] = -m[0] * m[5] * m[14] + m[0] * m[6] * m[13] + m[4] * m[1] * m[14] - m[4] * m[2] * m[13] -
            m[12] * m[1] * m[6] + m[12] * m[2] * m[5];
  inv[3] = -m[1] * m[6] * m[11] + m[1] * m[7] * m[10] + m[5] * m[2] * m[11] - m[5] * m[3] * m[10] -
           m[9] * m[2] * m[7] + m[9] * m[3] * m[6];
  inv[7] = m[0] * m[6] * m[11] - m[0] * m[7] * m[10] - m[4] * m[2] * m[11] + m[4] * m[3] * m[10] +
           m[8] * m[2] * m[7] - m[8] * m[3] * m[6];
  inv[11] = -m[0] * m[5] * m[11] + m[0] * m[7] * m[9] + m[4] * m[1] * m[11] - m[4] * m[3] * m[9] -
            m[8] * m[1] * m[7] + m[8] * m[3] * m[5];
  inv[15] = m[0] * m[5] * m[10] - m[0] * m[6] * m[9] - m[4] * m[1] * m[10] + m[4] * m[2] * m[9] +
            m[8] * m[1] * m[6] - m[8] * m[2] * m[5];
  const double det = m[0] * inv[0] + m[1] * inv[4] + m[2] * inv[8] + m[3] * inv[12];
  if (!std::isfinite(det) || det == 0) return false;
  for (int i = 0; i < 16; ++i) out[size_t(i)] = inv[size_t(i)] / det;
  for (double v : out)
    if (!std::isfinite(v)) return false;
  return true;
}

// inv * (x, y, z, w): homogeneous.
std::array<double, 4> apply(const Mat4& m, double x, double y, double z, double w) {
  std::array<double, 4> r{};
  for (int i = 0; i < 4; ++i)
    r[size_t(i)] = m[size_t(i)] * x + m[size_t(4 + i)] * y + m[size_t(8 + i)] * z + m[size_t(12 + i)] * w;
  return r;
}

bool point_of(const std::array<double, 4>& h, Vec3d& p) {
  if (!(std::fabs(h[3]) > 1e-300)) return false;
  p = {h[0] / h[3], h[1] / h[3], h[2] / h[3]};
  return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z);
}

// A camera's screen-sample rays onto the receiver plane: the one loop behind
// request_view's needs and view_samples' receivers.
struct Rays {
  Mat4 inv{};
  Vec3d eye{};
  bool perspective = false;
  double pixel = 0;  // one pixel's angle (perspective) or width (orthographic) at the centre
  double plane = 0, max_dist = 0;
  uint32_t sx = 0, sy = 0;

  // False when the matrix is not finite or not invertible, or casts no ray.
  bool init(const double* vp, uint32_t width, uint32_t samples_x, uint32_t samples_y, double plane_y, double max_d) {
    for (int i = 0; i < 16; ++i)
      if (!std::isfinite(vp[i])) return false;
    if (!invert(vp, inv)) return false;
    // The eye: the point the matrix sends to clip (0, 0, *, 0). None (w = 0): orthographic.
    perspective = point_of(apply(inv, 0, 0, 1, 0), eye);
    Vec3d c0{}, cx{}, c1{}, cx1{};
    const double dx = 2.0 / double(width);
    if (!point_of(apply(inv, 0, 0, 0.25, 1), c0) || !point_of(apply(inv, 0, 0, 0.75, 1), c1) ||
        !point_of(apply(inv, dx, 0, 0.25, 1), cx) || !point_of(apply(inv, dx, 0, 0.75, 1), cx1))
      return false;
    pixel = perspective ? length(normalize(cx - eye) - normalize(c0 - eye)) : length(cx - c0);
    plane = plane_y, max_dist = max_d, sx = samples_x, sy = samples_y;
    return std::isfinite(pixel);
  }
  // Sample (i, j)'s receiver p at distance t along its ray, its pixel's footprint there;
  // false for the sky, a ray parallel to the plane, or a receiver past max_dist.
  bool cast(uint32_t i, uint32_t j, Vec3d& p, double& t, double& footprint) const {
    const double nx = 2 * (i + 0.5) / sx - 1, ny = 2 * (j + 0.5) / sy - 1;
    Vec3d a{}, b{};
    if (!point_of(apply(inv, nx, ny, 0.25, 1), a) || !point_of(apply(inv, nx, ny, 0.75, 1), b)) return false;
    Vec3d origin = a, dir{};
    if (perspective) {
      origin = eye;
      dir = a - eye;
    } else {
      dir = b - a;
      Vec3d n{};
      if (point_of(apply(inv, nx, ny, -1, 1), n)) origin = n;  // the near plane (GL); [0, 1] depth: behind it
    }
    const double len = length(dir);
    if (!(len > 0)) return false;
    dir = dir / len;
    if (!(std::fabs(dir.y) > 1e-12)) return false;  // parallel to the receiver plane
    t = (plane - origin.y) / dir.y;
    if (!(t > 0) || t > max_dist) return false;  // sky, or too far
    p = origin + dir * t;
    footprint = perspective ? t * pixel : pixel;
    return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z);
  }
};

bool valid_view(const double* vp, uint32_t width, uint32_t height, const ViewOptions& o) {
  return vp && width != 0 && height != 0 && o.samples_x != 0 && o.samples_y != 0 &&
         uint64_t(o.samples_x) * o.samples_y <= kMaxViewSamples;
}

// The poses ahead (seconds after this request) at which a moving camera's needs are
// cast: the next frame's (dt on), then doubling up to `lookahead`, at most kAheadSteps.
constexpr int kAheadSteps = 6;
int ahead_times(double dt, double lookahead, std::array<double, kAheadSteps>& out) {
  if (!(dt > 0 && dt <= 1) || !(lookahead > 0) || !std::isfinite(lookahead)) return 0;
  lookahead = std::min(lookahead, 4.0);
  double tau = std::max(dt, lookahead / double(1 << (kAheadSteps - 1)));
  int n = 0;
  while (n < kAheadSteps) {
    out[size_t(n++)] = std::min(tau, lookahead);
    if (tau >= lookahead) break;
    tau *= 2;
  }
  return n;
}

}  // namespace

uint32_t RemoteMap::view_slots() const noexcept {
  const uint32_t slots = cache_.slot_count();
  const uint32_t headroom = std::max<uint32_t>(4, slots / 16);
  return slots > headroom ? slots - headroom : 1;
}

bool RemoteMap::in_other_view_locked(const View* self, uint64_t tile) const noexcept {
  for (const View& v : views_) {
    if (!v.used || &v == self) continue;
    const ViewTile key{tile, {}, 0, false, false, false};
    if (std::binary_search(v.tiles.begin(), v.tiles.end(), key, tile_less)) return true;
  }
  return false;
}

ViewStats RemoteMap::view_counts_locked(const View& v) const noexcept {
  ViewStats s;
  s.ok = true;
  s.wanted = v.wanted;
  for (const ViewTile& t : v.tiles) {
    if (t.ahead) {
      ++s.ahead;
      continue;
    }
    ++s.kept;
    const PageState st = cache_.lookup(t.tile).state;
    // An index tile the walk ended at is a need for its children: met only once the next
    // request walks through it (a path tile is met when resident).
    if (st == PageState::constant || (st == PageState::resident && (t.path || t.entry.kind != EntryKind::index)))
      ++s.resident;
  }
  return s;
}

ViewStats RemoteMap::view_stats(uint32_t id) const noexcept {
  std::shared_lock lock(mu_);
  for (const View& v : views_)
    if (v.used && v.id == id) return view_counts_locked(v);
  return {};
}

bool RemoteMap::remove_view(uint32_t id) noexcept {
  std::lock_guard vlock(views_mu_);
  std::lock_guard lock(mu_);
  for (View& v : views_) {
    if (!v.used || v.id != id) continue;
    size_t cancelled = 0;
    for (const ViewTile& t : v.tiles) {
      if (in_other_view_locked(&v, t.tile)) continue;
      const PageEntry pe = cache_.lookup(t.tile);
      if (pe.state == PageState::resident) slot_in_view_[pe.slot] = 0;
      RequestRecord* r = requests_.find(t.tile);
      if (!r) continue;
      if (r->state == RequestState::queued) {
        drop_locked(*r);
        ++cancelled;
      } else if (r->state == RequestState::sent && cancels_.size() < cancels_.capacity()) {
        cancels_.push_back(r->tile);
        r->state = RequestState::cancel_sent;
        ++cancelled;
      }
    }
    v.used = false;
    v.tiles.clear();  // keeps its capacity for the next view in this place
    --view_count_;
    if (cancelled) notifier_->notify();
    return true;
  }
  return false;
}

size_t RemoteMap::view_samples(const double* vp, uint32_t width, uint32_t height, const ViewOptions& o,
                               std::span<ViewSample> out) const noexcept {
  if (!valid_view(vp, width, height, o)) return 0;
  const double plane = std::isnan(o.receiver_height) ? surface_.ground : o.receiver_height;
  const double span = std::max(surface_.x1 - surface_.x0, surface_.z1 - surface_.z0);
  Rays rays;
  if (!rays.init(vp, width, o.samples_x, o.samples_y, plane, o.max_distance > 0 ? o.max_distance : 1.5 * span))
    return 0;
  size_t n = 0;
  for (uint32_t j = 0; j < o.samples_y; ++j)
    for (uint32_t i = 0; i < o.samples_x && n < out.size(); ++i) {
      Vec3d p{};
      double t = 0, footprint = 0;
      if (!rays.cast(i, j, p, t, footprint)) continue;
      out[n++] = ViewSample{WorldPoint{p.x, p.y, p.z}, float(footprint), float(t)};
    }
  return n;
}

template <class R>
void RemoteMap::collect_view_tiles(const R& rays, const ViewOptions& o, bool ahead, std::vector<ViewTile>& next) const {
  const uint32_t L = header_.map_level;
  // Levels the skip grid (<= K) and the map preview (<= K + p) answer exactly need no tile.
  const uint32_t exact = grid_.levels + preview_.levels();
  for (uint32_t j = 0; j < o.samples_y; ++j)
    for (uint32_t i = 0; i < o.samples_x; ++i) {
      Vec3d p{};
      double t = 0, footprint = 0;
      if (!rays.cast(i, j, p, t, footprint)) continue;
      // The level a lookup at p with this footprint reads first (filter_levels, as
      // visibility_filtered picks it from the same float footprint).
      const float fp = float(footprint);
      const uint32_t level = fp > 0 ? filter_levels(L, float(double(fp) / light_.texel_size(p, L))).fine : L;
      if (level <= exact) continue;
      const LightPoint lp = light_.to_light(p);
      if (!(lp.u >= 0 && lp.u < 1 && lp.v >= 0 && lp.v < 1)) continue;
      const auto [x, y] = LightSpace::texel_of(level, lp.u, lp.v);
      const float dist = float(t);
      auto resident_index = [&](uint64_t tid, const GridEntry& e) -> const CutGrid* {
        const PageEntry pe = cache_.lookup(tid);
        if (pe.state != PageState::resident) return nullptr;
        if (next.size() < next.capacity()) next.push_back(ViewTile{tid, e, dist, true, false, ahead});
        return &slot_grid_[pe.slot];
      };
      const PageHit hit = walk_page_table(grid_, level, x, y, resident_index);
      if (hit.kind == PageHit::Kind::value) continue;
      if (cache_.lookup(hit.tile).state == PageState::constant) continue;  // given up: coarse for good
      if (next.size() < next.capacity()) next.push_back(ViewTile{hit.tile, hit.entry, dist, false, false, ahead});
    }
}

namespace {
// Sorts `v` by tile and keeps one entry per tile: a need now over a need ahead, the
// nearest; a path tile only if every entry is one (a need anywhere: a need).
template <class T>
void dedup_tiles(std::vector<T>& v) {
  std::sort(v.begin(), v.end(), [](const T& a, const T& b) {
    if (a.tile != b.tile) return a.tile < b.tile;
    if (a.ahead != b.ahead) return !a.ahead;
    return a.distance < b.distance;
  });
  size_t n = 0;
  for (size_t k = 0; k < v.size(); ++k) {
    if (n > 0 && v[n - 1].tile == v[k].tile) {
      v[n - 1].path = v[n - 1].path && v[k].path;
      continue;
    }
    v[n++] = v[k];
  }
  v.resize(n);
}
}  // namespace

ViewStats RemoteMap::request_view(uint32_t id, const double* vp, uint32_t width, uint32_t height,
                                  const ViewOptions& o) noexcept {
  if (stack_grid_ || !valid_view(vp, width, height, o)) return {};
  const double plane = std::isnan(o.receiver_height) ? surface_.ground : o.receiver_height;
  const double span = std::max(surface_.x1 - surface_.x0, surface_.z1 - surface_.z0);
  const double max_dist = o.max_distance > 0 ? o.max_distance : 1.5 * span;
  Rays rays;
  if (!rays.init(vp, width, o.samples_x, o.samples_y, plane, max_dist)) return {};

  std::lock_guard vlock(views_mu_);
  View* view = nullptr;
  {
    std::lock_guard lock(mu_);
    for (View& v : views_)
      if (v.used && v.id == id) view = &v;
    if (!view) {
      for (View& v : views_)
        if (!v.used && !view) view = &v;
      if (!view) return {};  // kMaxViews others registered
      try {                  // a view's storage, once: bounded by kMaxViewSamples
        view->tiles.reserve(kMaxViewSamples);
        view->next.reserve(kMaxViewSamples);
        view->scratch.reserve(kMaxViewSamples);
      } catch (...) {
        return {};
      }
      view->used = true;
      view->id = id;
      view->wanted = 0;
      view->has_last = false;
      view->tiles.clear();
      ++view_count_;
    }
    view->priority = o.priority;
  }

  // ---- 1. the samples' tiles (lock shared: lookups go on), then the poses ahead ----
  std::vector<ViewTile>& next = view->next;
  next.clear();
  std::array<double, kAheadSteps> ahead{};
  const int steps = std::isfinite(o.time) && view->has_last ? ahead_times(o.time - view->last_time, o.lookahead, ahead) : 0;
  {
    std::shared_lock lock(mu_);
    collect_view_tiles(rays, o, false, next);
    // Each pose ahead: the matrix extrapolated along its change since the last request
    // (exact for a camera translating at constant velocity: M is affine in the eye).
    for (int s = 0; s < steps; ++s) {
      const double f = ahead[size_t(s)] / (o.time - view->last_time);
      double m[16];
      for (int e = 0; e < 16; ++e) m[e] = vp[e] + (vp[e] - view->last_vp[size_t(e)]) * f;
      Rays r;
      if (!r.init(m, width, o.samples_x, o.samples_y, plane, max_dist)) continue;
      if (next.capacity() - next.size() < size_t(o.samples_x) * o.samples_y) dedup_tiles(next);  // room for a pose
      collect_view_tiles(r, o, true, next);
    }
  }
  if (std::isfinite(o.time)) {
    std::copy(vp, vp + 16, view->last_vp.begin());
    view->last_time = o.time;
    view->has_last = true;
  } else {
    view->has_last = false;
  }
  // ---- 2. deduplicated, nearest first (the poses ahead after), cut to the view's share ----
  dedup_tiles(next);
  std::sort(next.begin(), next.end(), [](const ViewTile& a, const ViewTile& b) {
    if (a.ahead != b.ahead) return !a.ahead;
    return a.distance != b.distance ? a.distance < b.distance : a.tile < b.tile;
  });
  ViewStats out;
  out.ok = true;
  std::lock_guard lock(mu_);
  // The slots the views of higher priority (or equal, registered as another id) hold,
  // less the tiles this view shares with them: this view's share is what remains.
  std::vector<ViewTile>& mine = view->scratch;
  mine.assign(next.begin(), next.end());
  std::sort(mine.begin(), mine.end(), tile_less);
  uint64_t claimed = 0;
  for (const View& v : views_) {
    if (!v.used || &v == view || v.priority < view->priority) continue;
    for (const ViewTile& t : v.tiles)
      claimed += !std::binary_search(mine.begin(), mine.end(), t, tile_less);
  }
  const uint32_t slots = view_slots();
  const uint64_t floor_share = std::max<uint64_t>(1, slots / (2 * std::max<uint32_t>(1, view_count_)));
  const uint64_t share = std::max<uint64_t>(floor_share, claimed < slots ? slots - claimed : 0);
  view->wanted = uint32_t(std::count_if(next.begin(), next.end(), [](const ViewTile& t) { return !t.ahead; }));
  if (next.size() > share) {
    if (view->wanted > share) ++stats_.view_overflows;  // the pixels' own tiles do not fit
    next.resize(size_t(share));
  }
  // The view's resident tiles become the most recently used, farthest first (the nearest
  // last): eviction takes tiles no view touched since before this request.
  for (size_t k = next.size(); k-- > 0;) {
    const PageEntry pe = cache_.lookup(next[k].tile);
    if (pe.state != PageState::resident) continue;
    cache_.touch(pe.slot);
    slot_in_view_[pe.slot] = 1;
  }
  // Priorities by rank (nearest first), above the lookups' miss priority.
  const uint16_t lowest = uint16_t(std::min<uint32_t>(uint32_t(options_.miss_priority) + 1, 65535));
  for (size_t k = 0; k < next.size(); ++k) {
    const uint32_t p = o.priority > k ? uint32_t(o.priority - k) : 0;
    const uint16_t prio = uint16_t(std::max<uint32_t>(p, lowest));
    const PageState st = cache_.lookup(next[k].tile).state;
    if (st == PageState::absent || st == PageState::requested) out.queued += want_locked(next[k].tile, next[k].entry, prio);
  }
  // ---- 3. what left the view: cancelled unless another view holds it ----
  std::sort(next.begin(), next.end(), tile_less);
  size_t cancelled = 0;
  auto old = view->tiles.begin();
  for (ViewTile& t : next) {
    while (old != view->tiles.end() && old->tile < t.tile) ++old;
    const PageState st = cache_.lookup(t.tile).state;
    const bool resident = st == PageState::resident;
    if (old != view->tiles.end() && old->tile == t.tile) {
      if (old->seen_resident && !resident && st != PageState::constant) ++stats_.view_refetches;
      t.seen_resident = resident || (old->seen_resident && st != PageState::absent && st != PageState::requested);
    } else {
      t.seen_resident = resident;
    }
  }
  for (const ViewTile& t : view->tiles) {
    if (std::binary_search(next.begin(), next.end(), t, tile_less) || in_other_view_locked(view, t.tile)) continue;
    const PageEntry pe = cache_.lookup(t.tile);
    if (pe.state == PageState::resident) slot_in_view_[pe.slot] = 0;  // in no view now
    RequestRecord* r = requests_.find(t.tile);
    if (!r) continue;
    if (r->state == RequestState::queued) {
      drop_locked(*r);
      ++cancelled;
    } else if (r->state == RequestState::sent && cancels_.size() < cancels_.capacity()) {
      cancels_.push_back(r->tile);
      r->state = RequestState::cancel_sent;
      ++cancelled;
    }
  }
  view->tiles.swap(next);
  out.cancelled = uint32_t(cancelled);
  const ViewStats now = view_counts_locked(*view);
  out.wanted = now.wanted, out.kept = now.kept, out.resident = now.resident, out.ahead = now.ahead;
  if (cancelled || out.queued) notifier_->notify();
  return out;
}

}  // namespace st::client
