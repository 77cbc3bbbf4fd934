// A pinhole camera in world space (+Y up), shared by `shadowtile render`, `report` and
// the load tester's synthetic cameras. Header-only on purpose: the load tester (which
// must not link tiles/bake: Embree, OpenEXR) includes it without linking anything.
#pragma once
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "common/error.hpp"
#include "tiles/core/vec.hpp"

namespace st {

struct Camera {
  Vec3d pos, target;
  double fov_deg = 60;  // vertical field of view
  double aspect = 16.0 / 9.0;
};

// Orthonormal basis of a camera: forward, right, up (right-handed, +Y up).
struct CameraBasis {
  Vec3d forward, right, up;
  double tan_half_y = 0, tan_half_x = 0;
};

inline CameraBasis basis(const Camera& c) {
  CameraBasis b;
  b.forward = normalize(c.target - c.pos);
  Vec3d up{0, 1, 0};
  if (std::fabs(dot(b.forward, up)) > 0.999) up = {0, 0, 1};
  b.right = normalize(cross(b.forward, up));
  b.up = cross(b.right, b.forward);
  b.tan_half_y = std::tan(c.fov_deg * M_PI / 360.0);
  b.tan_half_x = b.tan_half_y * c.aspect;
  return b;
}

// Direction of the ray through normalized screen point (sx, sy) in [0,1]^2 (row 0 top).
inline Vec3d ray_dir(const CameraBasis& b, double sx, double sy) {
  const double px = (2 * sx - 1) * b.tan_half_x, py = (1 - 2 * sy) * b.tan_half_y;
  return normalize(b.forward + b.right * px + b.up * py);
}

// The camera's OpenGL view-projection matrix (gluLookAt then gluPerspective, NDC depth
// [-1, 1]), column-major as GL and glm store it: element (row r, column c) at [c * 4 + r].
// What client::Map::request_view takes.
inline std::array<double, 16> view_projection(const Camera& c, double near_plane, double far_plane) {
  const CameraBasis b = basis(c);
  const Vec3d s = b.right, u = b.up, f = b.forward;
  const double view[4][4] = {{s.x, s.y, s.z, -dot(s, c.pos)},
                             {u.x, u.y, u.z, -dot(u, c.pos)},
                             {-f.x, -f.y, -f.z, dot(f, c.pos)},
                             {0, 0, 0, 1}};
  const double fy = 1 / b.tan_half_y, n = near_plane, fa = far_plane;
  const double proj[4][4] = {{fy / c.aspect, 0, 0, 0},
                             {0, fy, 0, 0},
                             {0, 0, (fa + n) / (n - fa), 2 * fa * n / (n - fa)},
                             {0, 0, -1, 0}};
  std::array<double, 16> m{};
  for (int r = 0; r < 4; ++r)
    for (int col = 0; col < 4; ++col) {
      double v = 0;
      for (int k = 0; k < 4; ++k) v += proj[r][k] * view[k][col];
      m[size_t(col * 4 + r)] = v;
    }
  return m;
}
// "pos=X,Y,Z,target=X,Y,Z[,fov=DEG]"; throws st::Error naming the field.
inline Camera parse_camera(const std::string& text) {
  Camera c;
  bool pos = false, target = false;
  size_t i = 0;
  while (i < text.size()) {
    const size_t eq = text.find('=', i);
    if (eq == std::string::npos) throw Error("--camera: expected key=value in '" + text + "'");
    const std::string key = text.substr(i, eq - i);
    const int n = key == "fov" ? 1 : 3;
    double v[3] = {0, 0, 0};
    size_t p = eq + 1;
    for (int j = 0; j < n; ++j) {
      const size_t end = text.find(',', p);
      const std::string num = text.substr(p, end == std::string::npos ? std::string::npos : end - p);
      char* e = nullptr;
      v[j] = std::strtod(num.c_str(), &e);
      if (num.empty() || *e != 0 || !std::isfinite(v[j]))
        throw Error("--camera: field '" + key + "' needs " + std::to_string(n) + " number(s), got '" + num + "'");
      p = end == std::string::npos ? text.size() : end + 1;
    }
    if (key == "pos") c.pos = {v[0], v[1], v[2]}, pos = true;
    else if (key == "target") c.target = {v[0], v[1], v[2]}, target = true;
    else if (key == "fov") {
      if (!(v[0] > 1 && v[0] < 179)) throw Error("--camera: fov must be in (1, 179) degrees");
      c.fov_deg = v[0];
    } else {
      throw Error("--camera: unknown field '" + key + "' (pos, target, fov)");
    }
    i = p;
  }
  if (!pos || !target) throw Error("--camera: needs pos=X,Y,Z and target=X,Y,Z");
  if (length(c.target - c.pos) == 0) throw Error("--camera: target equals pos");
  return c;
}

inline std::string to_string(const Camera& c) {
  char buf[256];
  std::snprintf(buf, sizeof buf, "pos=%.9g,%.9g,%.9g,target=%.9g,%.9g,%.9g,fov=%.6g", c.pos.x, c.pos.y, c.pos.z,
                c.target.x, c.target.y, c.target.z, c.fov_deg);
  return buf;
}

}  // namespace st
