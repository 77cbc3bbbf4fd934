// Small .vdb files written with the OpenVDB API for the volume tests (tiles and client):
// a constant-density box and a voxelised ball, both fog volumes named "density" unless
// told otherwise. Only compiled when the build has OpenVDB (SHADOWTILE_HAVE_OPENVDB).
#pragma once
#include <openvdb/openvdb.h>

#include <cmath>
#include <string>

namespace st::vdbtest {

inline void init() { openvdb::initialize(); }

inline void write(const std::string& path, const openvdb::GridPtrVec& grids, bool stats = true) {
  init();
  openvdb::io::File f(path);
  f.setGridStatsMetadataEnabled(stats);
  f.write(grids);
  f.close();
}

// Voxels (0..nx-1, 0..ny-1, 0..nz-1) of size `voxel`, all `density` (one fill: active
// tiles where whole nodes are covered, voxels elsewhere), placed so that the box spans
// [origin, origin + n * voxel] in world.
inline openvdb::FloatGrid::Ptr box_grid(int nx, int ny, int nz, double voxel, openvdb::Vec3d origin,
                                        float density, const std::string& name = "density") {
  init();
  auto g = openvdb::FloatGrid::create(0.0f);
  g->setName(name);
  g->setGridClass(openvdb::GRID_FOG_VOLUME);
  auto xf = openvdb::math::Transform::createLinearTransform(voxel);
  xf->postTranslate(origin + openvdb::Vec3d(voxel / 2));  // voxel (0,0,0) centred at origin + voxel/2
  g->setTransform(xf);
  g->fill(openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(nx - 1, ny - 1, nz - 1)), density, true);
  return g;
}

// Voxels whose centre lies within `radius` of `centre` hold `density` (set one by one).
inline openvdb::FloatGrid::Ptr ball_grid(double radius, openvdb::Vec3d centre, double voxel, float density) {
  init();
  auto g = openvdb::FloatGrid::create(0.0f);
  g->setName("density");
  g->setGridClass(openvdb::GRID_FOG_VOLUME);
  g->setTransform(openvdb::math::Transform::createLinearTransform(voxel));
  auto acc = g->getAccessor();
  const int r = int(std::ceil(radius / voxel)) + 1;
  const openvdb::Coord c(int(std::lround(centre.x() / voxel)), int(std::lround(centre.y() / voxel)),
                         int(std::lround(centre.z() / voxel)));
  for (int z = -r; z <= r; ++z)
    for (int y = -r; y <= r; ++y)
      for (int x = -r; x <= r; ++x) {
        const openvdb::Coord ijk = c + openvdb::Coord(x, y, z);
        const openvdb::Vec3d w = g->transform().indexToWorld(ijk);
        if ((w - centre).length() <= radius) acc.setValue(ijk, density);
      }
  return g;
}

}  // namespace st::vdbtest
