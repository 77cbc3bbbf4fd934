// Cameras: Map::request_view (client.hpp). A view is a set of tiles, recomputed from the
// camera on every request:
//   1. (views_mu_, lock shared) each screen sample's ray meets the receiver plane at p;
//      its pixel's footprint there is t * pixel_angle (a perspective camera; an
//      orthographic one's is constant); the level is the finest whose texel
//      (LightSpace::texel_size) is no larger than the footprint, and levels <= K need
//      nothing (the skip grid answers). The page-table walk at p's texel of that level
//      names the tile needed (through resident index tiles, which are kept too).
//   2. The samples' tiles, deduplicated (nearest distance kept), are ordered nearest
//      first and cut to the view's share of view_slots(): views of higher priority claim
//      their tiles first, so a near camera is never starved by a minimap or a prefetch.
//   3. (lock exclusive) the tiles that left this view and are in no other have their
//      fetches cancelled (queued: dropped; sent: Cancel); the kept ones are wanted at
//      priority options.priority - rank; a tile seen resident before, still in the
//      view and now absent is counted as a refetch (MapStats::view_refetches).
// The slots of the views' tiles are flagged (slot_in_view_: set when a view takes a
// resident tile or a tile of a view arrives, cleared when it leaves every view), and
// before every eviction sync_lru_locked makes them the most recently used (one pass over
// the slots, which it makes anyway), so while the views' tiles fit in view_slots() the
// tile evicted is one no view holds (the rest of the slots: arrivals being filled and the
// lookups' own misses).
#include <algorithm>
#include <cmath>

#include "client/remote_map.hpp"

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

// The finest level whose texel (`texel0` world units at level 0) is no larger than
// `footprint`, clamped to [0, map_level] (the load tester's level_for_footprint).
uint32_t level_for(double texel0, double footprint, uint32_t map_level) {
  if (!(footprint > 0)) return map_level;
  const double l = std::ceil(std::log2(texel0 / footprint));
  if (!(l > 0)) return 0;
  return l >= double(map_level) ? map_level : uint32_t(l);
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
    const ViewTile key{tile, {}, 0, false, false};
    if (std::binary_search(v.tiles.begin(), v.tiles.end(), key, tile_less)) return true;
  }
  return false;
}

ViewStats RemoteMap::view_counts_locked(const View& v) const noexcept {
  ViewStats s;
  s.ok = true;
  s.wanted = v.wanted;
  s.kept = uint32_t(v.tiles.size());
  for (const ViewTile& t : v.tiles) {
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

ViewStats RemoteMap::request_view(uint32_t id, const double* vp, uint32_t width, uint32_t height,
                                  const ViewOptions& o) noexcept {
  if (stack_grid_ || !vp || width == 0 || height == 0 || o.samples_x == 0 || o.samples_y == 0 ||
      uint64_t(o.samples_x) * o.samples_y > kMaxViewSamples)
    return {};
  for (int i = 0; i < 16; ++i)
    if (!std::isfinite(vp[i])) return {};
  Mat4 inv;
  if (!invert(vp, inv)) return {};

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
      view->tiles.clear();
      ++view_count_;
    }
    view->priority = o.priority;
  }

  // ---- 1. the samples' tiles (lock shared: lookups go on) ----
  const uint32_t L = header_.map_level, K = grid_.levels;
  const double plane = std::isnan(o.receiver_height) ? surface_.ground : o.receiver_height;
  const double span = std::max(surface_.x1 - surface_.x0, surface_.z1 - surface_.z0);
  const double max_dist = o.max_distance > 0 ? o.max_distance : 1.5 * span;
  // The eye: the point the matrix sends to clip (0, 0, *, 0). None (w = 0): orthographic.
  Vec3d eye{};
  const bool perspective = point_of(apply(inv, 0, 0, 1, 0), eye);
  // One pixel's angle (perspective) or width (orthographic) at the screen's centre.
  Vec3d c0{}, c1{}, cx{}, cx1{};
  const double dx = 2.0 / double(width);
  if (!point_of(apply(inv, 0, 0, 0.25, 1), c0) || !point_of(apply(inv, 0, 0, 0.75, 1), c1) ||
      !point_of(apply(inv, dx, 0, 0.25, 1), cx) || !point_of(apply(inv, dx, 0, 0.75, 1), cx1))
    return {};
  double pixel = 0;
  if (perspective) {
    pixel = length(normalize(cx - eye) - normalize(c0 - eye));
  } else {
    pixel = length(cx - c0);
  }
  std::vector<ViewTile>& next = view->next;
  next.clear();
  {
    std::shared_lock lock(mu_);
    for (uint32_t j = 0; j < o.samples_y; ++j)
      for (uint32_t i = 0; i < o.samples_x; ++i) {
        const double nx = 2 * (i + 0.5) / o.samples_x - 1, ny = 2 * (j + 0.5) / o.samples_y - 1;
        Vec3d a{}, b{};
        if (!point_of(apply(inv, nx, ny, 0.25, 1), a) || !point_of(apply(inv, nx, ny, 0.75, 1), b)) continue;
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
        if (!(len > 0)) continue;
        dir = dir / len;
        if (!(std::fabs(dir.y) > 1e-12)) continue;  // parallel to the receiver plane
        const double t = (plane - origin.y) / dir.y;
        if (!(t > 0) || t > max_dist) continue;  // sky, or too far
        const Vec3d p = origin + dir * t;
        const double footprint = perspective ? t * pixel : pixel;
        const uint32_t level = level_for(light_.texel_size(p, 0), footprint, L);
        if (level <= K) continue;  // the skip grid answers
        const LightPoint lp = light_.to_light(p);
        if (!(lp.u >= 0 && lp.u < 1 && lp.v >= 0 && lp.v < 1)) continue;
        const auto [x, y] = LightSpace::texel_of(level, lp.u, lp.v);
        const float dist = float(t);
        auto resident_index = [&](uint64_t tid, const GridEntry& e) -> const CutGrid* {
          const PageEntry pe = cache_.lookup(tid);
          if (pe.state != PageState::resident) return nullptr;
          if (next.size() < next.capacity()) next.push_back(ViewTile{tid, e, dist, true, false});
          return &slot_grid_[pe.slot];
        };
        const PageHit hit = walk_page_table(grid_, level, x, y, resident_index);
        if (hit.kind == PageHit::Kind::value) continue;
        if (cache_.lookup(hit.tile).state == PageState::constant) continue;  // given up: coarse for good
        if (next.size() < next.capacity()) next.push_back(ViewTile{hit.tile, hit.entry, dist, false, false});
      }
  }
  // ---- 2. deduplicated, nearest first, cut to the view's share ----
  std::sort(next.begin(), next.end(), [](const ViewTile& a, const ViewTile& b) {
    return a.tile != b.tile ? a.tile < b.tile : a.distance < b.distance;
  });
  size_t n = 0;
  for (size_t k = 0; k < next.size(); ++k) {
    if (n > 0 && next[n - 1].tile == next[k].tile) {
      next[n - 1].path = next[n - 1].path && next[k].path;  // a need anywhere: a need
      continue;
    }
    next[n++] = next[k];
  }
  next.resize(n);
  std::sort(next.begin(), next.end(), [](const ViewTile& a, const ViewTile& b) {
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
  view->wanted = uint32_t(next.size());
  if (next.size() > share) {
    ++stats_.view_overflows;
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
  out.wanted = now.wanted, out.kept = now.kept, out.resident = now.resident;
  if (cancelled || out.queued) notifier_->notify();
  return out;
}

}  // namespace st::client
