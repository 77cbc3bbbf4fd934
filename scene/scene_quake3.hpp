// Quake 3 maps (IBSP version 46), read by our own bounds-checked parser: assimp 5.2.5's
// Q3BSP importer never produces valid meshes (its validation fails) and reads out of
// bounds on hostile files before validation runs (seen with assimp 5.2.5), so assimp never sees them.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "scene/scene.hpp"

namespace st {

inline constexpr int kQuake3PatchLevel = 8;
// The most triangles, and the most vertices, a map may emit (after skipping sky, nodraw
// and billboards; counted before any allocation): faces may share vertex ranges and a
// 3x3 patch block becomes 128 triangles, so without a cap a file of a few hundred KB can
// ask for gigabytes. Real maps stay far below (hundreds of thousands of triangles).
inline constexpr uint64_t kQuake3MaxTriangles = uint64_t(1) << 22;
// The largest .bsp (file or .pk3 member) read; real maps take tens of MB. A member is
// checked to start with "IBSP" before its stated size is inflated.
inline constexpr uint64_t kQuake3MaxBspBytes = uint64_t(256) << 20;

// Loads a .bsp file, or from a .pk3 (zip) the member `member` when given, else the first
// member under maps/ ending in .bsp (else the first .bsp member). load_scene() accepts
// "ARCHIVE.pk3:maps/NAME.bsp" to pick a member. One st::Mesh per texture, named after it ("untextured"
// for index -1). Polygon (1) and mesh (3) faces are read from their mesh vertices; Bezier
// patches (2) are tessellated into kQuake3PatchLevel x kQuake3PatchLevel quads per 3x3
// control block; billboards (4) and faces whose texture is sky (SURF_SKY 0x4) or
// invisible (SURF_NODRAW 0x80) are skipped: they cast no shadow in the game. Each face is
// wound so that its geometric normal agrees with its stored vertex normals. Quake 3 is
// Z-up: pass UpAxis::z. Throws st::Error naming the file (and member) and the field at
// fault for any structural inconsistency, and for maps past kQuake3MaxTriangles
// triangles or vertices.
// `max_output` as for load_quake3_bytes below.
Scene load_quake3(const std::string& path, const SceneOptions& options, const std::string& member = "",
                  uint64_t max_output = kQuake3MaxTriangles);

// The same from bytes already in memory: a .pk3 archive when `is_pk3`, else a bare .bsp;
// `name` stands for the file in the scene name and in error messages.
// `max_output` bounds the triangles and the vertices the map may emit (tests and the
// fuzz harness pass less than the default, kQuake3MaxTriangles).
Scene load_quake3_bytes(std::vector<uint8_t> bytes, const std::string& name, bool is_pk3,
                        const SceneOptions& options, const std::string& member = "",
                        uint64_t max_output = kQuake3MaxTriangles);

}  // namespace st
