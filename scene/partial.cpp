#include "scene/partial.hpp"

#include <algorithm>
#include <cmath>

#include "common/error.hpp"

namespace st {

bool AlphaTexture::solid(float u, float v) const {
  if (!std::isfinite(u) || !std::isfinite(v) || width == 0 || height == 0) return false;
  const double fu = double(u) - std::floor(double(u));
  const double fv = double(v) - std::floor(double(v));
  const uint32_t x = std::min(width - 1, uint32_t(fu * width));
  const uint32_t y = std::min(height - 1, uint32_t(fv * height));
  return alpha[size_t(y) * width + x] >= cutoff * 255.0f;
}

void AlphaTexture::validate() const {
  if (width == 0 || height == 0 || alpha.size() != size_t(width) * height)
    throw Error("alpha texture '" + name + "': " + std::to_string(width) + "x" +
                std::to_string(height) + " does not match " + std::to_string(alpha.size()) +
                " texels");
  if (!(cutoff >= 0 && cutoff <= 1))
    throw Error("alpha texture '" + name + "': cutoff is not in [0, 1]");
}

void Volume::validate() const {
  if (bounds.empty() || !is_finite(bounds.lo) || !is_finite(bounds.hi))
    throw Error("volume '" + name + "': empty or non-finite bounds");
  if (nx == 0 || ny == 0 || nz == 0 || density.size() != size_t(nx) * ny * nz)
    throw Error("volume '" + name + "': grid " + std::to_string(nx) + "x" +
                std::to_string(ny) + "x" + std::to_string(nz) + " does not match " +
                std::to_string(density.size()) + " densities");
  for (size_t i = 0; i < density.size(); ++i)
    if (!std::isfinite(density[i]) || density[i] < 0)
      throw Error("volume '" + name + "': density " + std::to_string(i) +
                  " is negative or not finite");
  for (float s : sigma)
    if (!std::isfinite(s) || s < 0)
      throw Error("volume '" + name + "': sigma is negative or not finite");
}

float Volume::density_at(const Vec3d& p) const {
  if (density.empty()) return 0;
  const Vec3d e = bounds.extent();
  // Voxel centres at (i + 0.5) / n of the extent.
  const double gx = (p.x - bounds.lo.x) / e.x * nx - 0.5;
  const double gy = (p.y - bounds.lo.y) / e.y * ny - 0.5;
  const double gz = (p.z - bounds.lo.z) / e.z * nz - 0.5;
  if (!(gx >= -0.5 && gx <= nx - 0.5 && gy >= -0.5 && gy <= ny - 0.5 && gz >= -0.5 &&
        gz <= nz - 0.5))
    return 0;
  auto axis = [](double g, uint32_t n, uint32_t& i0, uint32_t& i1, double& f) {
    const double c = std::clamp(g, 0.0, double(n - 1));
    i0 = uint32_t(std::floor(c));
    i1 = std::min(i0 + 1, n - 1);
    f = c - i0;
  };
  uint32_t x0, x1, y0, y1, z0, z1;
  double fx, fy, fz;
  axis(gx, nx, x0, x1, fx);
  axis(gy, ny, y0, y1, fy);
  axis(gz, nz, z0, z1, fz);
  auto at = [&](uint32_t x, uint32_t y, uint32_t z) {
    return double(density[(size_t(z) * ny + y) * nx + x]);
  };
  const double c00 = at(x0, y0, z0) * (1 - fx) + at(x1, y0, z0) * fx;
  const double c10 = at(x0, y1, z0) * (1 - fx) + at(x1, y1, z0) * fx;
  const double c01 = at(x0, y0, z1) * (1 - fx) + at(x1, y0, z1) * fx;
  const double c11 = at(x0, y1, z1) * (1 - fx) + at(x1, y1, z1) * fx;
  const double c0 = c00 * (1 - fy) + c10 * fy;
  const double c1 = c01 * (1 - fy) + c11 * fy;
  return float(c0 * (1 - fz) + c1 * fz);
}

namespace {

// The part [a, b] of [t0, t1] where origin + t dir lies inside `box` (slab test).
bool clip(const Aabb& box, const Vec3d& o, const Vec3d& d, double t0, double t1, double& a,
          double& b) {
  a = t0;
  b = t1;
  for (int k = 0; k < 3; ++k) {
    const double lo = box.lo[k], hi = box.hi[k];
    if (d[k] == 0) {
      if (o[k] < lo || o[k] > hi) return false;
      continue;
    }
    double ta = (lo - o[k]) / d[k], tb = (hi - o[k]) / d[k];
    if (ta > tb) std::swap(ta, tb);
    a = std::max(a, ta);
    b = std::min(b, tb);
  }
  return a < b;
}

// The steps of march(), handed to `step(t, tau)` one by one (no allocation).
template <class Step>
void march_steps(const Volume& vol, const Vec3d& origin, const Vec3d& dir, double t0, double t1,
                 Step&& step) {
  double a, b;
  if (vol.density.empty() || !clip(vol.bounds, origin, dir, t0, t1, a, b)) return;
  const Vec3d e = vol.bounds.extent();
  const double voxel = std::min({e.x / vol.nx, e.y / vol.ny, e.z / vol.nz});
  const double speed = length(dir);
  if (!(speed > 0)) return;
  const double max_dt = 0.5 * voxel / speed;
  const auto steps = uint64_t(std::ceil((b - a) / max_dt));
  const uint64_t n = std::clamp<uint64_t>(steps, 1, 1u << 20);
  const double dt = (b - a) / double(n);
  Rgb tau{0, 0, 0};
  step(a, tau);
  for (uint64_t i = 0; i < n; ++i) {
    const double tm = a + (double(i) + 0.5) * dt;
    const double rho = vol.density_at(origin + dir * tm) * dt * speed;
    for (int c = 0; c < 3; ++c) tau[c] += float(rho * vol.sigma[c]);
    step(i + 1 == n ? b : a + double(i + 1) * dt, tau);
  }
}

}  // namespace

void Volume::march(const Vec3d& origin, const Vec3d& dir, double t0, double t1,
                   std::vector<Step>& out) const {
  out.clear();
  march_steps(*this, origin, dir, t0, t1, [&](double t, const Rgb& tau) { out.push_back({t, tau}); });
}

Rgb Volume::optical_depth(const Vec3d& origin, const Vec3d& dir, double t0,
                          double t1) const {
  Rgb last{0, 0, 0};
  march_steps(*this, origin, dir, t0, t1, [&](double, const Rgb& tau) { last = tau; });
  return last;
}

}  // namespace st
