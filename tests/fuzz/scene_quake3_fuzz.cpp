// libFuzzer harness for the Quake 3 map reader (scene/scene_quake3.hpp). Input:
// byte 0 is a control byte (bit 0: the rest is a .pk3 archive, else a bare .bsp; bit 1:
// Z-up; bit 2: name the member "maps/a.bsp" instead of picking one), the rest the file.
// load_quake3_bytes must either throw st::Error or return a scene that holds what
// append_mesh promises: indices in range, finite vertices, meshes partitioning the
// triangles, and no more triangles than the bound passed (kFuzzMaxOutput: small, so that
// executions stay fast; the default bound is exercised by scene_quake3_test).
#include <cmath>

#include "common/error.hpp"
#include "tests/fuzz/quake3_seeds.hpp"
#include "scene/scene_quake3.hpp"

std::vector<st::fuzz::Bytes> st::fuzz::seeds() {
  std::vector<Bytes> out;
  const std::vector<Bytes> maps = quake3_maps(3);
  for (size_t i = 0; i < maps.size(); ++i) {
    // Maps whose faces are all billboards/sky have no shadow casters: not seeds.
    Bytes bare = maps[i];
    bare.insert(bare.begin(), uint8_t(i % 2 ? 2 : 0));
    out.push_back(std::move(bare));
    if (i % 3 == 0) {
      Bytes pk3 = zip_archive({{"readme.txt", Bytes{'h', 'i'}}, {"maps/a.bsp", maps[i]}}, i % 2 == 1);
      pk3.insert(pk3.begin(), uint8_t(1 | (i % 2 ? 4 : 0)));
      out.push_back(std::move(pk3));
    }
  }
  return out;
}

namespace {
constexpr uint64_t kFuzzMaxOutput = 1 << 15;
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const uint8_t control = data[0];
  std::vector<std::uint8_t> file(data + 1, data + size);
  st::SceneOptions options;
  options.up = control & 2 ? st::UpAxis::z : st::UpAxis::y;
  st::Scene scene;
  try {
    scene = st::load_quake3_bytes(std::move(file), "fuzz", control & 1, options, control & 4 ? "maps/a.bsp" : "",
                                  kFuzzMaxOutput);
  } catch (const st::Error&) {
    return 0;
  }
  FUZZ_CHECK(!scene.triangles.empty());
  FUZZ_CHECK(scene.triangles.size() <= kFuzzMaxOutput && scene.vertices.size() <= kFuzzMaxOutput);
  for (const auto& t : scene.triangles)
    for (uint32_t v : t) FUZZ_CHECK(v < scene.vertices.size());
  for (const auto& v : scene.vertices) FUZZ_CHECK(std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z));
  uint64_t next = 0;
  for (const auto& m : scene.meshes) {
    FUZZ_CHECK(m.first_triangle == next);
    next += m.triangle_count;
  }
  FUZZ_CHECK(next == scene.triangles.size());
  st::fuzz::note_accepted();
  return 0;
}
