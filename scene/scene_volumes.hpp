// Volumes a scene spec adds to a scene (deep shadow maps, DSM 2000 §5.5 "volumes"): density
// grids read from OpenVDB files and a procedural fog layer. Both become st::Volume
// (partial.hpp): a dense grid whose extinction the deep sampler ray-marches.
//
// Spec grammar (load_scene, scene.hpp):
//   vdb:PATH[,grid=NAME][,scale=S][,sigma=S][,max_voxels=N]
//       a scene holding one volume: the float grid NAME ("density" by default) of the
//       OpenVDB file PATH (no comma in PATH); a PATH ending in ".vdb" alone means the same
//       with the defaults.
//   BASE+vdb:PATH[,...]    BASE (any spec: a file, procedural:..., vdb:...) plus that volume
//   BASE+fog:density=D[,height=H][,bottom=Y0][,top=Y1][,res=N]
//       BASE plus a fog layer over BASE's footprint (its x, z bounds) from y = Y0 (default
//       the bottom of BASE) to Y1 (default its top): extinction D per unit length at Y0,
//       falling as exp(-(y - Y0) / H) when H > 0 (height fog), homogeneous when H = 0
//       (the default).
// Several "+vdb:" and "+fog:" parts may follow one another; each applies to what is left
// of it (a fog over BASE+vdb: covers the volume's footprint too).
//
// OpenVDB grids (load_vdb_volume):
//   - the grid must be a float grid (FloatGrid; a fog volume, not a level set), its voxel
//     values finite and >= 0 after `scale`; inactive voxels are empty (density 0);
//   - world placement from the grid's transform: a linear map whose index axes stay the
//     world axes (scale and translation, any sign, per axis). Rotated or sheared grids and
//     frustum (non-linear) transforms are refused with one line; OpenVDB's voxel (i, j, k)
//     is centred on index point (i, j, k), so the volume spans the active voxels' bounding
//     box [min - 1/2, max + 1/2] mapped to world; UpAxis::z turns it like mesh files;
//   - memory: the grid is made dense over that box, so a box of more than `max_voxels`
//     voxels (default kVdbVoxelBudget = 2^26, 256 MiB of float; at most kVdbMaxVoxels =
//     2^30) is refused before anything dense is allocated: first from the file's own
//     statistics (OpenVDB writes the bounding box with each grid), then from the grid read.
//     The grid itself is read whole by OpenVDB first (its sparse size, about the file's
//     uncompressed size);
//   - hostile files: the file's structure (every length and offset up to each grid's
//     topology, truncation, a float root's node counts) is checked before OpenVDB reads
//     it (scene_vdb.cpp says what is left to OpenVDB), and OpenVDB reads in a child
//     process with a memory limit and a timeout (it crashes or allocates whatever a
//     voxel buffer's length says on some corrupt files), so that a crash there is one
//     line of error too;
//   - every failure (missing or truncated file, not a .vdb, a grid not there, another
//     value type, a level set, a bad transform, too big, a bad value) is one st::Error
//     line naming the file and grid.
// Fog (fog_layer): a 1 x n x 1 grid (constant across x and z, linear in y between cell
// centres, constant in the half cells at the bottom and top), its n chosen so that a cell
// is at most H / 8 thick (the line between two cell centres is then within
// (1/8)^2 / 8 = 0.2% of exp above it) and of optical depth at most 0.2, so a march's
// half-cell step (Volume::march) takes tau at most 0.1 and exp(-tau) between steps is
// within 0.0013 of the line between them; at most kFogMaxCells cells. The march still
// steps every half cell along the whole ray (the volume's cost is the length of the ray
// in cells, as for any grid): integrating it analytically would need a Volume that is
// not a grid.
#pragma once
#include <cstdint>
#include <string>

#include "scene/scene.hpp"

namespace st {

constexpr uint64_t kVdbVoxelBudget = uint64_t(1) << 26;  // dense voxels by default
constexpr uint64_t kVdbMaxVoxels = uint64_t(1) << 30;    // the largest max_voxels accepted
constexpr uint32_t kFogMaxCells = 1u << 16;

struct VdbOptions {
  std::string grid = "density";
  double scale = 1;  // multiplies every density
  double sigma = 1;  // extinction per unit density and unit length (grey)
  uint64_t max_voxels = kVdbVoxelBudget;
  UpAxis up = UpAxis::y;
};

// Whether this shadowtile reads .vdb files (built with OpenVDB).
bool vdb_supported();

// One grid of an OpenVDB file as a volume (named "PATH:GRID"). Throws st::Error (one line).
Volume load_vdb_volume(const std::string& path, const VdbOptions& options);

struct FogOptions {
  double density = 0;  // extinction per unit length at `bottom`
  double height = 0;   // scale height H; 0: homogeneous
  double bottom = 0, top = 0;
  uint32_t cells = 0;  // 0: chosen as described above
};
// The fog layer over `footprint`'s x and z extent, from options.bottom to options.top.
Volume fog_layer(const Aabb& footprint, const FogOptions& options);

// The position of the first "+vdb:" or "+fog:" part of a spec (std::string::npos: none).
size_t volume_suffix(const std::string& spec);
// Adds the volumes of `parts` ("+vdb:...+fog:...", as volume_suffix() found them) to
// `scene`; `up` applies to the .vdb files. Throws st::Error naming the part at fault.
void add_spec_volumes(Scene& scene, const std::string& parts, UpAxis up);
// A scene of one volume from "vdb:PATH[,...]" or a bare "PATH.vdb".
Scene load_vdb_scene(const std::string& spec, UpAxis up);

}  // namespace st
