// Test support: writing a Scene through assimp's exporters, so that the scene tests can
// read back files of every format the loader claims to read (no product code writes
// scenes: it is compiled into tiles_tests only).
#pragma once
#include <string>

#include "scene/scene.hpp"

namespace st {

// Writes `scene` to `path` with the assimp exporter `format_id` ("obj", "ply", "plyb",
// "gltf2", "glb2", "collada", "fbx", "stl", "3ds", ...): one node and one mesh per
// st::Mesh, identity transforms, one plain material. Vertices are stored as float (the
// formats' precision), so coordinates far from the origin lose bits. Throws st::Error
// naming the file on an unknown format id or a failed export.
void write_scene(const Scene& scene, const std::string& path, const std::string& format_id);

}  // namespace st
