// Hostile scene files (SECURITY.md "Reading files"): each test writes a small file that
// once cost gigabytes, minutes or a crash, and checks for one line of error, fast, with the
// memory of this process and of the reader child bounded (getrusage's max RSS).
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <thread>

#include "common/error.hpp"
#include "tiles/bake/canonical_coverage.hpp"
#include "image/png_io.hpp"
#include "scene/scene.hpp"
#include "scene/scene_header_check.hpp"
#include "scene/scene_isolated.hpp"
#include "scene/scene_limits.hpp"

namespace st {
namespace scene_hostile_test {

std::string dir_of(const std::string& name) {
  const std::string d = std::string(SHADOWTILE_TEST_TMP) + "/scene_hostile_" + name;
  std::filesystem::create_directories(d);
  return d;
}

void write_bytes(const std::string& path, const std::string& bytes) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  f.write(bytes.data(), std::streamsize(bytes.size()));
  ASSERT_TRUE(f.good()) << path;
}

uint64_t max_rss_mib(int who) {
  rusage u{};
  getrusage(who, &u);
  return uint64_t(u.ru_maxrss) >> 10;  // KiB on Linux
}

struct Outcome {
  std::string error;  // "(no error)" when it loaded
  double seconds = 0;
};

// Loads `path`, expecting one line of error; the time it took.
Outcome load_error(const std::string& path, const SceneLimits& limits = {}) {
  Outcome o{"(no error)", 0};
  const auto t0 = std::chrono::steady_clock::now();
  try {
    load_scene(path, {}, limits);
  } catch (const Error& e) {
    o.error = e.what();
  }
  o.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(o.error.find('\n'), std::string::npos) << o.error;
  return o;
}

#if defined(__SANITIZE_ADDRESS__)
constexpr bool kAsan = true;  // shadow memory and quarantine inflate resident memory
#else
constexpr bool kAsan = false;
#endif

// Neither this process nor any reader child it ran went past `mib` of resident memory
// (three times that under ASan).
void expect_memory_below(uint64_t mib) {
  const uint64_t bound = kAsan ? 3 * mib : mib;
  EXPECT_LT(max_rss_mib(RUSAGE_SELF), bound);
  EXPECT_LT(max_rss_mib(RUSAGE_CHILDREN), bound);
}

TEST(SceneHostile, PlyCountClaimsAreCheckedAgainstTheFileSize) {
  const std::string d = dir_of("ply");
  // A vertex count of 2^28 in a file of a few hundred bytes (assimp reserved for it: 3 GiB).
  std::string ascii = "ply\nformat ascii 1.0\nelement vertex 268435456\nproperty float x\nproperty float y\n"
                      "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
  ascii += "0 0 0\n1 0 0\n0 1 0\n";
  ascii += "3 0 1 2\n";
  write_bytes(d + "/count.ply", ascii);
  // Binary: 12 bytes a vertex; 40,000 claimed in 120 bytes of body.
  std::string binary = "ply\nformat binary_little_endian 1.0\nelement vertex 40000\nproperty float x\n"
                       "property float y\nproperty float z\nend_header\n" + std::string(120, '\0');
  write_bytes(d + "/binary.ply", binary);
  for (const char* f : {"/count.ply", "/binary.ply"}) {
    const Outcome o = load_error(d + f);
    EXPECT_NE(o.error.find("PLY header claims"), std::string::npos) << o.error;
    EXPECT_NE(o.error.find("'vertex' elements"), std::string::npos) << o.error;
    EXPECT_LT(o.seconds, 5.0);
  }
  // The same header with its 3 vertices stated truthfully loads.
  std::string good = ascii;
  good.replace(good.find("268435456"), 9, "3");
  write_bytes(d + "/good.ply", good);
  EXPECT_EQ(load_scene(d + "/good.ply").triangles.size(), 1u);
  expect_memory_below(512);
}

TEST(SceneHostile, OffCountClaimsAreCheckedAgainstTheFileSize) {
  const std::string d = dir_of("off");
  // assimp's own invalid/OutOfMemory.off (309 bytes: 15.8 GB and 67 s before its error).
  std::string off = "OFF\n353535235358 6 0\n";
  const char* corners[8] = {"-0.5 -0.5 0.5", "0.5 -0.5 0.5", "-0.5 0.5 0.5", "0.5 0.5 0.5",
                            "-0.5 0.5 -0.5", "0.5 0.5 -0.5", "-0.5 -0.5 -0.5", "0.5 -0.5 -0.5"};
  for (const char* c : corners) off += std::string(c) + "\n";
  off += "4 0 1 3 2\n4 2 3 5 4\n4 4 5 7 6\n4 6 7 1 0\n4 1 7 5 3\n4 6 0 2 4\n";
  write_bytes(d + "/oom.off", off);
  const Outcome o = load_error(d + "/oom.off");
  EXPECT_NE(o.error.find("OFF header claims 353535235358 vertices"), std::string::npos) << o.error;
  EXPECT_LT(o.seconds, 5.0);
  // Stated truthfully, the cube loads (12 triangles, closed).
  std::string good = off;
  good.replace(good.find("353535235358"), 12, "8");
  write_bytes(d + "/cube.off", good);
  const Scene s = load_scene(d + "/cube.off");
  EXPECT_EQ(s.triangles.size(), 12u);
  expect_memory_below(512);
}

// A binary glTF: one buffer of `triangles` triangles (non-indexed), one mesh whose
// `primitives` primitives all use that one accessor, `nodes` nodes instancing the mesh
// (`with_mesh`) or bare.
std::string glb(uint32_t triangles, uint32_t primitives, uint32_t nodes, bool with_mesh) {
  std::string bin;
  for (uint32_t t = 0; t < triangles; ++t)
    for (float v : {float(t), 0.0f, 0.0f, float(t) + 1, 0.0f, 0.0f, float(t), 1.0f, 0.0f})
      bin.append(reinterpret_cast<const char*>(&v), 4);
  const uint32_t n = 3 * triangles;
  std::string prims;
  for (uint32_t p = 0; p < primitives; ++p) prims += std::string(p ? "," : "") + "{\"attributes\":{\"POSITION\":0}}";
  std::string node_list, roots;
  for (uint32_t i = 0; i < nodes; ++i) {
    node_list += std::string(i ? "," : "") + (with_mesh ? "{\"mesh\":0}" : "{}");
    roots += std::string(i ? "," : "") + std::to_string(i);
  }
  std::string json = "{\"asset\":{\"version\":\"2.0\"},\"buffers\":[{\"byteLength\":" + std::to_string(bin.size()) +
                     "}],\"bufferViews\":[{\"buffer\":0,\"byteLength\":" + std::to_string(bin.size()) +
                     "}],\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":" + std::to_string(n) +
                     ",\"type\":\"VEC3\",\"min\":[0,0,0],\"max\":[" + std::to_string(triangles) +
                     ",1,0]}],\"meshes\":[{\"primitives\":[" + prims + "]}],\"nodes\":[" + node_list +
                     "],\"scenes\":[{\"nodes\":[" + roots + "]}],\"scene\":0}";
  while (json.size() % 4) json += ' ';
  auto u32 = [](uint32_t v) { return std::string(reinterpret_cast<const char*>(&v), 4); };
  const uint32_t total = 12 + 8 + uint32_t(json.size()) + 8 + uint32_t(bin.size());
  return "glTF" + u32(2) + u32(total) + u32(uint32_t(json.size())) + "JSON" + json + u32(uint32_t(bin.size())) +
         "BIN" + std::string(1, '\0') + bin;
}

TEST(SceneHostile, GltfInstancesAreCountedAgainstTheTriangleBudgetBeforeCopying) {
  const std::string d = dir_of("gltf");
  // 100 nodes x 100 primitives x 1,000 triangles: 10^7 triangles from 36 KB.
  write_bytes(d + "/instanced.glb", glb(1000, 100, 100, true));
  const Outcome o = load_error(d + "/instanced.glb");
  EXPECT_NE(o.error.find("instances more than 4194304 triangles"), std::string::npos) << o.error;
  EXPECT_NE(o.error.find("--scene-limits triangles="), std::string::npos) << o.error;
  EXPECT_LT(o.seconds, 10.0);
  // Raising the budget lets a smaller one through, every instance kept.
  write_bytes(d + "/small.glb", glb(10, 4, 5, true));
  SceneLimits l;
  l.max_triangles = 200;
  EXPECT_EQ(load_scene(d + "/small.glb", {}, l).meshes.size(), 20u);
  l.max_triangles = 199;
  EXPECT_NE(load_error(d + "/small.glb", l).error.find("instances more than 199"), std::string::npos);
  expect_memory_below(512);
}

TEST(SceneHostile, ManyGltfNodesStopAtTheReadersMemoryLimit) {
  const std::string d = dir_of("nodes");
  SceneLimits l;
  l.memory_bytes = uint64_t(256) << 20;
  // 300,000 bare nodes (5 MB; 10^6 in 59 MB took assimp 2.35 GiB): more than 256 MiB hold
  // at one aiNode each, refused from the JSON before assimp runs.
  write_bytes(d + "/nodes.glb", glb(1, 1, 300000, false));
  const Outcome o = load_error(d + "/nodes.glb", l);
  EXPECT_NE(o.error.find("glTF file has 300000 nodes"), std::string::npos) << o.error;
  EXPECT_NE(o.error.find("256 MiB (raise it with --scene-limits memory=MIB)"), std::string::npos) << o.error;
  EXPECT_LT(o.seconds, 10.0);
  l.memory_bytes = uint64_t(64) << 20;
  // 55,000 pass that count but not assimp's real cost per node (about 1.7 KB): the reader
  // runs out of its limit, in one line. Under ASan the limit is a resident-memory watch with
  // room for the sanitizer's own overhead (scene_isolated.hpp), too loose for this file.
  if (kAsan) GTEST_SKIP() << "the address-space limit is off under ASan";
  // The limit is address space above the child's size at the fork: free heap this process
  // already holds (after many tests in one process) is reusable on top, so there the file
  // may load; in a fresh process (ctest runs each case alone, the CLI loads first) it
  // cannot. Either way the child stays within this process's footprint + the limit.
  write_bytes(d + "/fewer.glb", glb(1, 1, 55000, false));
  const Outcome f = load_error(d + "/fewer.glb", l);
  if (f.error != "(no error)") {
    EXPECT_NE(f.error.find("out of memory reading it: the reader's limit of 64 MiB"), std::string::npos) << f.error;
  }
  EXPECT_LT(f.seconds, 20.0);
  EXPECT_LT(max_rss_mib(RUSAGE_CHILDREN), max_rss_mib(RUSAGE_SELF) + 64 + 256);
  expect_memory_below(1024);
}

TEST(SceneHostile, DeeplyNestedXmlIsRefusedBeforeAssimpRecurses) {
  const std::string d = dir_of("xml");
  // COLLADA nodes nested 300,000 deep crashed assimp (SIGSEGV); 2,000 show the check.
  std::string dae = "<?xml version=\"1.0\"?>\n<!-- <node> in a comment --><COLLADA version=\"1.4.1\">"
                    "<library_visual_scenes><visual_scene id=\"s\">";
  for (int i = 0; i < 2000; ++i) dae += "<node id=\"n" + std::to_string(i) + "\" name=\"a/b\">";
  for (int i = 0; i < 2000; ++i) dae += "</node>";
  dae += "</visual_scene></library_visual_scenes><scene><instance_visual_scene url=\"#s\"/></scene></COLLADA>\n";
  write_bytes(d + "/deep.dae", dae);
  const Outcome o = load_error(d + "/deep.dae");
  EXPECT_NE(o.error.find("XML elements nest deeper than 1024 levels"), std::string::npos) << o.error;
  EXPECT_LT(o.seconds, 5.0);
  // Self-closing elements, comments, CDATA and quoted '>' do not count as nesting.
  std::string flat = "<?xml version=\"1.0\"?><a>";
  for (int i = 0; i < 3000; ++i) flat += "<b x=\"1>2\"/><!-- <c> --><![CDATA[<d>]]>";
  flat += "</a>";
  write_bytes(d + "/flat.xml", flat);
  EXPECT_NO_THROW(check_xml_nesting(d + "/flat.xml"));
}

TEST(SceneHostile, AlphaTexturesShareOneTexelBudgetCheckedFromTheirHeaders) {
  const std::string d = dir_of("textures");
  std::vector<uint8_t> ga;
  for (int i = 0; i < 256 * 256; ++i) ga.insert(ga.end(), {200, uint8_t(i % 2 ? 255 : 0)});
  std::string mtl, obj = "mtllib m.mtl\nvt 0 0\nvt 1 0\nvt 0 1\n";
  for (int i = 0; i < 3; ++i) {
    const std::string n = std::to_string(i);
    write_png_grey_alpha(d + "/t" + n + ".png", 256, 256, ga);
    mtl += "newmtl m" + n + "\nmap_d t" + n + ".png\n";
    obj += "v 0 " + n + " 0\nv 1 " + n + " 0\nv 0 " + n + " 1\nusemtl m" + n + "\nf " + std::to_string(3 * i + 1) +
           "/1 " + std::to_string(3 * i + 2) + "/2 " + std::to_string(3 * i + 3) + "/3\n";
  }
  write_bytes(d + "/m.mtl", mtl);
  write_bytes(d + "/m.obj", obj);
  SceneLimits l;
  l.max_texels = 3 * 256 * 256;
  EXPECT_EQ(load_scene(d + "/m.obj", {}, l).alpha_textures.size(), 3u);
  l.max_texels = 3 * 256 * 256 - 1;
  const Outcome o = load_error(d + "/m.obj", l);
  EXPECT_NE(o.error.find("t2.png' has 65536 texels, which takes the scene's alpha textures past 196607"),
            std::string::npos)
      << o.error;
}

// The reader child: crashes, hangs and runaway allocations of whatever it runs end in one
// line each, within the limits.
TEST(SceneHostile, TheReaderChildContainsCrashesHangsAndMemory) {
  const std::string path = dir_of("child") + "/any.obj";
  auto error_of = [&](const SceneLimits& l, const std::function<Scene()>& read) {
    try {
      read_scene_isolated(path, l, read);
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("(no error)");
  };
  SceneLimits l;
  EXPECT_NE(error_of(l, []() -> Scene { std::abort(); }).find("the scene reader crashed on it (SIGABRT)"),
            std::string::npos);
  EXPECT_EQ(error_of(l, []() -> Scene { throw Error("its own words"); }), "its own words");
  l.seconds = 1;
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_NE(error_of(l, []() -> Scene {
              std::this_thread::sleep_for(std::chrono::seconds(60));
              return {};
            }).find("took longer than the reader's limit of 1 s"),
            std::string::npos);
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 5.0);
  l.seconds = 50;
  l.memory_bytes = uint64_t(64) << 20;
  const std::string oom = error_of(l, []() -> Scene {
    std::vector<std::unique_ptr<char[]>> blocks;
    for (int i = 0; i < 8192; ++i) {  // 8 GiB at most
      blocks.emplace_back(new char[size_t(1) << 20]);
      std::memset(blocks.back().get(), 1, size_t(1) << 20);
    }
    return {};
  });
  EXPECT_NE(oom.find("out of memory reading it: the reader's limit of 64 MiB"), std::string::npos) << oom;
  expect_memory_below(1024);
  // A scene comes back whole.
  const Scene s = read_scene_isolated(path, {}, [] { return make_procedural("procedural:forest,trees=1,leaves=6"); });
  EXPECT_EQ(s.content_hash(), make_procedural("procedural:forest,trees=1,leaves=6").content_hash());
}

// 100,000 closed meshes entered and left at the same depths (coincident copies of one
// solid): the exit counting per ray is linear in them (it was quadratic: a file of such
// copies kept `bounds` busy for minutes on a small map).
TEST(SceneHostile, ExitCountingIsLinearInCoincidentClosedMeshes) {
  constexpr uint32_t kMeshes = 100000;
  std::vector<CanonicalHit> hits;
  for (uint32_t m = 0; m < kMeshes; ++m) hits.push_back({0.25, 2 * m, m, -1, true});
  for (uint32_t m = 0; m < kMeshes; ++m) hits.push_back({0.75, 2 * m + 1, m, +1, true});
  const auto t0 = std::chrono::steady_clock::now();
  const CanonicalResult r = canonical_interval(hits, 1.0);
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(r.lo_t, 0.25);
  EXPECT_EQ(r.hi_t, 0.75);
  EXPECT_FALSE(r.fell_back);
  // 0.23 s measured (release, loaded machine); the quadratic search took 11.4 s. The test
  // file compiles at -O0 under the sanitizers, and this header is inline: more room there.
  const double bound = kAsan ? 5.0 : 1.0;
  EXPECT_LT(s, bound);
  // Stacked and touching: mesh m spans [m, m + 1], so the ray goes on through all of them
  // and every mesh it met stays counted.
  hits.clear();
  for (uint32_t m = 0; m < kMeshes; ++m) {
    hits.push_back({double(m), 2 * m, m, -1, true});
    hits.push_back({double(m + 1), 2 * m + 1, m, +1, true});
  }
  std::sort(hits.begin(), hits.end());
  const auto t1 = std::chrono::steady_clock::now();
  const CanonicalResult stacked = canonical_interval(hits, 2.0 * kMeshes);
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count(), bound);
  EXPECT_EQ(stacked.lo_t, 0.0);
  EXPECT_EQ(stacked.hi_t, double(kMeshes));
  EXPECT_FALSE(stacked.fell_back);
}

struct StringSink final : SceneSink {
  std::string bytes;
  void put(const void* d, size_t n) override { bytes.append(static_cast<const char*>(d), n); }
};
struct StringSource final : SceneSource {
  std::string bytes;
  size_t at = 0;
  void get(void* d, size_t n) override {
    if (n > bytes.size() - at) throw Error("end of answer");
    std::memcpy(d, bytes.data() + at, n);
    at += n;
  }
};

TEST(SceneHostile, AnswersAreCheckedAgainstTheLimitsAndTheirOwnStructure) {
  const Scene scene = make_procedural("procedural:forest,trees=1,leaves=6");
  ASSERT_FALSE(scene.alpha_textures.empty());
  ASSERT_FALSE(scene.triangle_uv.empty());
  StringSink sink;
  write_scene_answer(sink, scene);
  auto decode = [&](const std::string& bytes, const SceneLimits& l = {}) {
    StringSource src;
    src.bytes = bytes;
    return read_scene_answer(src, "f", l);
  };
  EXPECT_EQ(decode(sink.bytes).content_hash(), scene.content_hash());
  // Every truncation fails: the first 256 lengths, then a spread over the rest.
  for (size_t n = 0; n < sink.bytes.size(); n += n < 256 ? 1 : sink.bytes.size() / 97 + 1)
    EXPECT_THROW(decode(sink.bytes.substr(0, n)), Error) << n;
  // Counts past the limits are refused before anything is allocated for them.
  SceneLimits l;
  l.max_triangles = scene.triangles.size() - 1;
  EXPECT_THROW(decode(sink.bytes, l), Error);
  l = {};
  l.max_texels = 1;
  EXPECT_THROW(decode(sink.bytes, l), Error);
  std::string huge = sink.bytes;
  const uint64_t claim = uint64_t(1) << 40;
  std::memcpy(huge.data() + 20, &claim, 8);  // triangles
  EXPECT_THROW(decode(huge), Error);
  // A triangle index past the vertices.
  std::string bad = sink.bytes;
  const uint32_t past = uint32_t(scene.vertices.size());
  std::memcpy(bad.data() + 68 + scene.vertices.size() * 24, &past, 4);
  EXPECT_THROW(decode(bad), Error);
  StringSink err;
  write_error_answer(err, "a\nb");
  try {
    decode(err.bytes);
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_STREQ(e.what(), "a b");
  }
}

TEST(SceneHostile, SceneLimitsParse) {
  const SceneLimits l = parse_scene_limits("memory=4096,seconds=600,triangles=100000000,texels=5,isolate=0");
  EXPECT_EQ(l.memory_bytes, uint64_t(4096) << 20);
  EXPECT_EQ(l.seconds, 600);
  EXPECT_EQ(l.max_triangles, 100000000u);
  EXPECT_EQ(l.max_texels, 5u);
  EXPECT_FALSE(l.isolate);
  const SceneLimits none = parse_scene_limits("none");
  EXPECT_EQ(none.memory_bytes, 0u);
  EXPECT_TRUE(none.isolate);
  EXPECT_EQ(parse_scene_limits("").max_triangles, SceneLimits{}.max_triangles);  // the option not given
  for (const char* bad : {"memory", "memory=-1", "colour=3", "triangles=0", "isolate=2", "seconds=1.5", ",", "memory=1,"})
    EXPECT_THROW(parse_scene_limits(bad), Error) << bad;
}

}  // namespace scene_hostile_test
}  // namespace st
