// libFuzzer harness for the OpenVDB scene reader (scene/scene_vdb.cpp,
// load_vdb_volume): our structure check of the file (every length against the bytes
// left, every offset against the file's size) runs before OpenVDB reads a byte of it.
// Input: the file's bytes, written to a per-process temporary file (OpenVDB reads files).
// load_vdb_volume must throw st::Error (one line) or return a volume within the voxel
// budget whose dimensions match its densities, all finite and non-negative.
#include <unistd.h>

#include <cmath>
#include <fstream>
#include <sstream>
#include <string>

#include "common/error.hpp"
#include "tests/fuzz/fuzz_harness.hpp"
#include "tests/tiles/vdb_fixtures.hpp"
#include "scene/scene_volumes.hpp"

namespace {

constexpr uint64_t kBudget = uint64_t(1) << 16;  // voxels: small, so a hostile file is cheap

std::string temp_path() {
  return "/tmp/shadowtile_vdb_fuzz_" + std::to_string(::getpid()) + ".vdb";
}

st::fuzz::Bytes file_bytes(const openvdb::GridPtrVec& grids, bool stats) {
  const std::string path = temp_path();
  st::vdbtest::write(path, grids, stats);
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  const std::string b = s.str();
  ::unlink(path.c_str());
  return st::fuzz::Bytes(b.begin(), b.end());
}

}  // namespace

std::vector<st::fuzz::Bytes> st::fuzz::seeds() {
  using st::vdbtest::ball_grid;
  using st::vdbtest::box_grid;
  std::vector<Bytes> out;
  out.push_back(file_bytes({box_grid(4, 3, 5, 0.5, {0, 0, 0}, 0.5f)}, true));
  out.push_back(file_bytes({box_grid(9, 2, 3, 1.0, {-2, 1, 0}, 2.0f)}, false));
  out.push_back(file_bytes({ball_grid(2.0, {0, 0, 0}, 0.5, 1.0f)}, true));
  out.push_back(file_bytes({box_grid(2, 2, 2, 0.25, {0, 0, 0}, 1.0f, "other"),
                            box_grid(3, 3, 3, 0.25, {1, 1, 1}, 0.75f)},
                           true));
  return out;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size > (1u << 20)) return 0;
  const std::string path = temp_path();
  {
    std::ofstream f(path, std::ios::binary | std::ios::trunc);
    f.write(reinterpret_cast<const char*>(data), std::streamsize(size));
  }
  st::VdbOptions o;
  o.max_voxels = kBudget;
  try {
    const st::Volume v = st::load_vdb_volume(path, o);
    FUZZ_CHECK(v.nx > 0 && v.ny > 0 && v.nz > 0);
    FUZZ_CHECK(uint64_t(v.nx) * v.ny * v.nz <= kBudget);
    FUZZ_CHECK(v.density.size() == size_t(v.nx) * v.ny * v.nz);
    for (float d : v.density) FUZZ_CHECK(std::isfinite(d) && d >= 0);
    st::fuzz::note_accepted();
  } catch (const st::Error& e) {
    const std::string what = e.what();
    FUZZ_CHECK(!what.empty() && what.find('\n') == std::string::npos);
  }
  ::unlink(path.c_str());
  return 0;
}
