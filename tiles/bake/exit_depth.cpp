// Exit-depth counting of one texel ray: see exit_depth.hpp for the rules.
#include "tiles/bake/exit_depth.hpp"

#include <algorithm>
#include <cmath>

namespace st {

// Applies the gathered group to the per-mesh counters (MH §3; voxel §6.1). False when
// the counters can no longer be trusted; `closed_hits` receives the number of closed
// hits in the group (open ones are ignored).
bool ExitDepthRay::apply_group(uint32_t& closed_hits) {
  closed_hits = 0;
  if (overflow_) return false;
  // Per mesh: the sign of its summed facings.
  uint32_t meshes[kMaxGroup];
  int32_t sums[kMaxGroup];
  uint32_t n = 0;
  for (uint32_t i = 0; i < n_group_; ++i) {
    if (!is_closed(group_[i])) continue;  // open: ignored inside closed objects
    ++closed_hits;
    const uint32_t prim = uint32_t(group_[i]);
    const uint32_t m = faces_->mesh(prim);
    const int32_t facing = faces_->facing(prim, dir_);
    uint32_t j = 0;
    while (j < n && meshes[j] != m) ++j;
    if (j == n) meshes[n] = m, sums[n] = 0, ++n;
    sums[j] += facing;
  }
  for (uint32_t j = 0; j < n; ++j) {
    const int32_t net = std::clamp(sums[j], -1, 1);
    if (net == 0) continue;
    uint32_t k = 0;
    while (k < n_mesh_ && mesh_[k] != meshes[j]) ++k;
    if (k == n_mesh_) {
      if (net < 0 || n_mesh_ == kMaxMeshes) return false;
      mesh_[k] = meshes[j], count_[k] = 0, ++n_mesh_;
    }
    count_[k] += net;
    total_ += net;
    if (count_[k] < 0) return false;  // never trust a negative counter
  }
  return true;
}

inline void ExitDepthRay::mark_group_done() {
  for (uint32_t k = 0; k < n_group_; ++k) done_[n_done_++] = group_[k];
}

// The next traversal: from just below the last group (inclusive; processed primitives
// are excluded by id) to the end of the ray, or the look-ahead window around the exit.
inline void ExitDepthRay::prepare_traversal() {
  window_ = exit_t_ != kNoHit;
  tnear_ = window_ ? std::max(t_min_, exit_t_ - look_ahead_)
                   : std::max(t_min_, floor_t_ - backoff_);
  tfar_ = window_ ? std::min(t_max_, exit_t_ + look_ahead_) : t_max_;
  best_t_ = kNoHit, n_group_ = 0, overflow_ = false;
}

bool ExitDepthRay::first_traversal_done() {
  lo_t_ = best_t_;
  hi_t_ = lo_t_;
  uint32_t closed_hits = 0;
  if (!apply_group(closed_hits) || n_group_ > kMaxDone) {
    fell_back_ = true;  // e.g. the first closed hit is a back face: hi = lo
    return false;
  }
  // Open first hit (MH §3: hi = lo) or a grazing touch that enters nothing: hi = lo.
  if (closed_hits == 0 || total_ == 0) return false;
  mark_group_done();
  floor_t_ = best_t_;
  prepare_traversal();
  return true;
}

// Depth peeling (MH §3.1) until every counter is back to 0, then one look-ahead confirms
// the exit or finds a touching entry.
bool ExitDepthRay::traversal_done() {
  ++traversals_;
  bool trusted = n_done_ + n_group_ <= kMaxDone && !overflow_;
  if (window_) {
    // Keep the closed hits whose exact t touches the exit; drop the rest (they lie beyond
    // a real gap and are met again by a later traversal if the ray goes on).
    uint32_t keep = 0;
    for (uint32_t k = 0; k < n_group_; ++k) {
      if (!is_closed(group_[k])) continue;
      if (faces_->plane_t(uint32_t(group_[k]), origin_, dir_) <= exit_d_ + touch_)
        group_[keep++] = group_[k];
    }
    n_group_ = keep;
    if (trusted && keep == 0) {
      hi_t_ = exit_t_;  // confirmed: nothing touches the exit
      return false;
    }
  } else if (n_group_ == 0) {
    trusted = false;  // left the scene inside a closed object: do not trust it
  }
  if (trusted) {
    uint32_t closed_hits = 0;
    trusted = apply_group(closed_hits) && traversals_ < kMaxTraversals;
  }
  if (!trusted) {
    fell_back_ = true;
    return false;
  }
  mark_group_done();
  if (window_) {
    // Touching entry: inside again; go on from the exit (inclusive) so that window hits
    // which did not touch are still met in order.
    if (total_ > 0) floor_t_ = exit_t_, exit_t_ = kNoHit;
  } else {
    floor_t_ = best_t_;
    if (total_ == 0) {
      bool touchable = false;
      for (uint32_t k = 0; k < n_group_; ++k)
        touchable |= is_closed(group_[k]) && faces_->touchable[uint32_t(group_[k])] != 0;
      record_exit_group();
      if (!touchable) {  // nothing can touch this exit: no look-ahead needed
        hi_t_ = best_t_;
        return false;
      }
      exit_t_ = best_t_;
      exit_d_ = -INFINITY;
      for (uint32_t k = 0; k < n_group_; ++k)
        if (is_closed(group_[k]))
          exit_d_ = std::max(exit_d_, faces_->plane_t(uint32_t(group_[k]), origin_, dir_));
    }
  }
  prepare_traversal();
  return true;
}

}  // namespace st
