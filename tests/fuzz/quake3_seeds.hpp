// Quake 3 maps and zip archives built byte by byte (the layouts scene_quake3.cpp and
// scene_zip.cpp read), for the seed corpora of scene_quake3_fuzz and scene_zip_fuzz.
#pragma once
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "tests/fuzz/fuzz_harness.hpp"

namespace st::fuzz {

// Small valid IBSP 46 maps: polygon, mesh and patch faces (3x3 up to 7x5 control grids),
// sky and nodraw textures, billboards, untextured faces. Deterministic in `seed`.
std::vector<Bytes> quake3_maps(uint64_t seed);

// A zip archive of `files`, each stored (method 0) or raw-deflated (method 8).
Bytes zip_archive(const std::vector<std::pair<std::string, Bytes>>& files, bool deflated);

}  // namespace st::fuzz
