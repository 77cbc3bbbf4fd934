// Quake 3 maps (.bsp, .pk3): the tests build their own maps and archives byte by byte,
// load good ones back and feed truncated and corrupted ones, which must give a clear
// st::Error and never a crash (the reason assimp is kept away from them).
#include <gtest/gtest.h>
#include <zlib.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "scene/scene.hpp"
#include "scene/scene_mesh.hpp"
#include "scene/scene_quake3.hpp"
#include "common/error.hpp"

namespace st {
namespace scene_quake3_test {

std::string tmp(const std::string& name) {
  std::filesystem::create_directories(SHADOWTILE_TEST_TMP);
  return std::string(SHADOWTILE_TEST_TMP) + "/scene_quake3_" + name;
}

void write_bytes(const std::string& path, const std::string& bytes) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  f.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(f.good()) << path;
}

template <class T>
void put(std::string& out, T v) {
  out.append(reinterpret_cast<const char*>(&v), sizeof v);  // little-endian host
}

std::string error_of(const std::string& path, SceneOptions options = {}) {
  try {
    load_scene(path, options);
  } catch (const Error& e) {
    EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << e.what();
    return e.what();
  }
  return "(no error)";
}

// ---- building maps ------------------------------------------------------------------

struct Vertex {
  Vec3d position, normal;
};
struct Face {
  int32_t texture, type, vertex, nvert, meshvert, nmeshvert, patch_w = 0, patch_h = 0;
};
struct Texture {
  std::string name;
  int32_t flags;
};

std::string bsp(const std::vector<Texture>& textures, const std::vector<Vertex>& vertices,
                const std::vector<int32_t>& meshverts, const std::vector<Face>& faces) {
  std::string lump[17];
  for (auto& t : textures) {
    std::string rec = t.name;
    rec.resize(64, '\0');
    put(rec, t.flags), put<int32_t>(rec, 1);
    lump[1] += rec;
  }
  for (auto& v : vertices) {
    for (double c : {v.position.x, v.position.y, v.position.z}) put(lump[10], float(c));
    for (int k = 0; k < 4; ++k) put(lump[10], 0.0f);  // uv, lightmap uv
    for (double c : {v.normal.x, v.normal.y, v.normal.z}) put(lump[10], float(c));
    put<uint32_t>(lump[10], 0xffffffffu);
  }
  for (int32_t m : meshverts) put(lump[11], m);
  for (auto& f : faces) {
    for (int32_t v : {f.texture, -1, f.type, f.vertex, f.nvert, f.meshvert, f.nmeshvert, -1}) put(lump[13], v);
    lump[13] += std::string(96 - 32, '\0');
    put(lump[13], f.patch_w), put(lump[13], f.patch_h);
  }
  std::string out = "IBSP";
  put<int32_t>(out, 46);
  int32_t at = 8 + 17 * 8;
  for (auto& l : lump) {
    put(out, l.empty() ? 0 : at), put(out, int32_t(l.size()));
    at += int32_t(l.size());
  }
  for (auto& l : lump) out += l;
  return out;
}

std::string deflate_raw(const std::string& in) {
  z_stream z{};
  EXPECT_EQ(deflateInit2(&z, 6, Z_DEFLATED, -MAX_WBITS, 8, Z_DEFAULT_STRATEGY), Z_OK);
  std::string out(deflateBound(&z, in.size()), '\0');
  z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(in.data()));
  z.avail_in = static_cast<uInt>(in.size());
  z.next_out = reinterpret_cast<Bytef*>(out.data());
  z.avail_out = static_cast<uInt>(out.size());
  EXPECT_EQ(deflate(&z, Z_FINISH), Z_STREAM_END);
  out.resize(z.total_out);
  deflateEnd(&z);
  return out;
}

// A zip archive (what a .pk3 is); members are deflated when `deflated`.
std::string zip(const std::vector<std::pair<std::string, std::string>>& files, bool deflated) {
  std::string out, central;
  for (auto& [name, data] : files) {
    const uint32_t offset = static_cast<uint32_t>(out.size());
    const uint32_t crc = static_cast<uint32_t>(crc32(0, reinterpret_cast<const Bytef*>(data.data()), uInt(data.size())));
    const std::string body = deflated ? deflate_raw(data) : data;
    const uint16_t method = deflated ? 8 : 0, name_len = static_cast<uint16_t>(name.size());
    const uint32_t packed = static_cast<uint32_t>(body.size()), size = static_cast<uint32_t>(data.size());
    put<uint32_t>(out, 0x04034b50u);
    for (uint16_t v : {uint16_t(20), uint16_t(0), method, uint16_t(0), uint16_t(0)}) put(out, v);
    put(out, crc), put(out, packed), put(out, size), put(out, name_len), put<uint16_t>(out, 0);
    out += name + body;
    put<uint32_t>(central, 0x02014b50u);
    for (uint16_t v : {uint16_t(20), uint16_t(20), uint16_t(0), method, uint16_t(0), uint16_t(0)}) put(central, v);
    put(central, crc), put(central, packed), put(central, size), put(central, name_len);
    for (uint16_t v : {0, 0, 0, 0}) put(central, v);  // extra, comment, disk, internal attributes
    put<uint32_t>(central, 0), put(central, offset);
    central += name;
  }
  const uint32_t cd_at = static_cast<uint32_t>(out.size()), cd_size = static_cast<uint32_t>(central.size());
  out += central;
  put<uint32_t>(out, 0x06054b50u);
  const uint16_t n = static_cast<uint16_t>(files.size());
  for (uint16_t v : {uint16_t(0), uint16_t(0), n, n}) put(out, v);
  put(out, cd_size), put(out, cd_at), put<uint16_t>(out, 0);
  return out;
}

// A 64-unit cube (Quake is Z-up) as six polygon faces of four vertices each, stored
// clockwise from outside as Quake 3 does, with outward normals; a flat 3x3 patch at
// z = 100 facing up; a sky quad at z = 500 (must be skipped); a billboard (skipped).
std::string test_map() {
  std::vector<Vertex> v;
  std::vector<int32_t> mv;
  std::vector<Face> faces;
  const int quads[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};
  const Vec3d normals[6] = {{-1, 0, 0}, {1, 0, 0}, {0, -1, 0}, {0, 1, 0}, {0, 0, -1}, {0, 0, 1}};
  for (int q = 0; q < 6; ++q) {
    const int32_t first = int32_t(v.size());
    for (int c : quads[q]) v.push_back({Vec3d{double(c & 1), double(c >> 1 & 1), double(c >> 2 & 1)} * 64, normals[q]});
    faces.push_back({0, 1, first, 4, int32_t(mv.size()), 6});
    for (int32_t m : {0, 2, 1, 0, 3, 2}) mv.push_back(m);  // clockwise from outside
  }
  const int32_t patch_first = int32_t(v.size());
  for (int j = 0; j < 3; ++j)
    for (int i = 0; i < 3; ++i) v.push_back({{32.0 * i, 32.0 * j, 100}, {0, 0, 1}});
  faces.push_back({1, 2, patch_first, 9, 0, 0, 3, 3});
  const int32_t sky_first = int32_t(v.size());
  for (auto p : {Vec3d{-1000, -1000, 500}, Vec3d{1000, -1000, 500}, Vec3d{1000, 1000, 500}, Vec3d{-1000, 1000, 500}})
    v.push_back({p, {0, 0, -1}});
  faces.push_back({2, 1, sky_first, 4, int32_t(mv.size()), 6});
  for (int32_t m : {0, 1, 2, 0, 2, 3}) mv.push_back(m);
  faces.push_back({0, 4, 0, 1, 0, 0});  // billboard
  return bsp({{"textures/base/wall", 0}, {"textures/base/curve", 0}, {"textures/skies/blue", 0x4}}, v, mv, faces);
}

void expect_test_map(const Scene& s) {
  ASSERT_EQ(s.meshes.size(), 2u);
  EXPECT_EQ(s.meshes[0].name, "textures/base/wall");
  EXPECT_EQ(s.meshes[1].name, "textures/base/curve");
  EXPECT_TRUE(s.meshes[0].closed);  // split per face in the file, welded at load
  EXPECT_FALSE(s.meshes[1].closed);
  EXPECT_EQ(s.meshes[0].triangle_count, 12u);
  EXPECT_EQ(s.meshes[1].triangle_count, 2u * kQuake3PatchLevel * kQuake3PatchLevel);
  // Faces were turned to agree with their normals, so nothing needed a flip by volume.
  EXPECT_EQ(s.stats.meshes_flipped, 0u);
  EXPECT_DOUBLE_EQ(mesh_signed_volume(s, 0), 64.0 * 64 * 64);
  // Z-up turned to Y-up: (x, y, z) -> (x, z, -y). The sky quad at height 500 is gone.
  const Aabb b = s.bounds();
  EXPECT_EQ(b.lo, (Vec3d{0, 0, -64}));
  EXPECT_EQ(b.hi, (Vec3d{64, 100, 0}));
  // The patch faces up (+Y after the turn).
  const auto& t = s.triangles[s.meshes[1].first_triangle];
  EXPECT_GT(cross(s.vertices[t[1]] - s.vertices[t[0]], s.vertices[t[2]] - s.vertices[t[0]]).y, 0);
}

// ---- tests --------------------------------------------------------------------------

TEST(Quake3, MapInStoredAndDeflatedPk3AndBareBspLoads) {
  const std::string map = test_map();
  const SceneOptions z_up{UpAxis::z};
  for (bool deflated : {false, true}) {
    const std::string path = tmp(deflated ? "deflated.pk3" : "stored.pk3");
    write_bytes(path, zip({{"readme.txt", "hello"}, {"maps/test.bsp", map}}, deflated));
    SCOPED_TRACE(path);
    expect_test_map(load_scene(path, z_up));
  }
  // Picking a member: the second map of a pack by name, and a clear error for a wrong one.
  const std::string pack = tmp("pack.pk3");
  const std::string other = bsp({{"textures/x", 0}}, {{{0, 0, 0}, {0, 0, 1}}, {{1, 0, 0}, {0, 0, 1}}, {{0, 1, 0}, {0, 0, 1}}},
                                {0, 1, 2}, {{0, 1, 0, 3, 0, 3}});
  write_bytes(pack, zip({{"maps/a.bsp", other}, {"maps/test.bsp", map}}, true));
  EXPECT_EQ(load_scene(pack, z_up).triangles.size(), 1u);  // the first map by default
  const Scene picked = load_scene(pack + ":maps/test.bsp", z_up);
  EXPECT_EQ(picked.name, pack + ":maps/test.bsp");
  expect_test_map(picked);
  EXPECT_NE(error_of(pack + ":maps/none.bsp").find("no map 'maps/none.bsp'"), std::string::npos);
  EXPECT_NE(error_of(tmp("missing.pk3") + ":maps/a.bsp").find("not found"), std::string::npos);

  const std::string bare = tmp("bare.bsp");
  write_bytes(bare, map);
  expect_test_map(load_scene(bare, z_up));
  EXPECT_EQ(load_scene(bare, z_up).content_hash(), load_scene(tmp("stored.pk3"), z_up).content_hash());
}

TEST(Quake3, MapsLoadUprightWithoutBeingToldAndAGivenAxisOverrides) {
  const std::string path = tmp("upright.bsp");
  write_bytes(path, test_map());
  const Scene s = load_scene(path);  // Quake 3 is Z-up: turned without SceneOptions::up
  expect_test_map(s);
  EXPECT_EQ(up_axis_text(s), "z (Quake 3 maps are Z-up)");
  const Scene as_written = load_scene(path, SceneOptions{UpAxis::y});
  EXPECT_EQ(up_axis_text(as_written), "y (given)");
  EXPECT_EQ(as_written.bounds().hi, (Vec3d{64, 64, 100}));  // height stays along +Z
}

TEST(Quake3, BadArchivesAndMapsGiveClearErrors) {
  std::string empty_map = "IBSP";
  put<int32_t>(empty_map, 46);
  for (int lump = 0; lump < 17; ++lump) put<int32_t>(empty_map, 0), put<int32_t>(empty_map, 0);
  std::string hostile = "IBSP";
  put<int32_t>(hostile, 46);
  for (int lump = 0; lump < 17; ++lump) put<int32_t>(hostile, 0x7fff0000), put<int32_t>(hostile, 4096);
  // A sound layout whose one face indexes mesh vertices it does not have.
  const std::string bad_face = bsp({}, {{{0, 0, 0}, {0, 0, 1}}, {{1, 0, 0}, {0, 0, 1}}, {{0, 1, 0}, {0, 0, 1}}},
                                   {}, {{-1, 1, 0, 3, 0, 3}});
  const std::string bad_index = bsp({}, {{{0, 0, 0}, {0, 0, 1}}, {{1, 0, 0}, {0, 0, 1}}, {{0, 1, 0}, {0, 0, 1}}},
                                    {0, 1, 7}, {{-1, 1, 0, 3, 0, 3}});
  const std::string bad_patch = bsp({}, {{{0, 0, 0}, {0, 0, 1}}}, {}, {{-1, 2, 0, 1, 0, 0, 3, 3}});
  const std::string bad_texture = bsp({}, {{{0, 0, 0}, {0, 0, 1}}}, {}, {{5, 1, 0, 1, 0, 0}});
  struct Case {
    std::vector<std::pair<std::string, std::string>> files;
    const char* want;
  };
  const Case cases[] = {{{}, "no .bsp map in the archive"},
                        {{{"readme.txt", "no map in here"}}, "no .bsp map in the archive"},
                        {{{"maps/a.bsp", empty_map}}, "no shadow-casting surfaces"},
                        {{{"maps/a.bsp", hostile}}, "lump 0 (offset 2147418112, size 4096) lies outside"},
                        {{{"maps/a.bsp", "IBSP"}}, "shorter than the 144-byte header"},
                        {{{"maps/a.bsp", "VBSP" + hostile.substr(4)}}, "'maps/a.bsp' does not start with 'IBSP'"},
                        {{{"maps/a.bsp", bad_face}}, "maps/a.bsp: malformed Quake 3 map: face 0: mesh-vertex range"},
                        {{{"maps/a.bsp", bad_index}}, "face 0: mesh vertex 7 outside"},
                        {{{"maps/a.bsp", bad_patch}}, "face 0: patch size 3x3"},
                        {{{"maps/a.bsp", bad_texture}}, "face 0: texture index out of range"}};
  int k = 0;
  for (auto& c : cases) {
    const std::string path = tmp("bad" + std::to_string(k++) + ".pk3");
    write_bytes(path, zip(c.files, false));
    const std::string msg = error_of(path);
    EXPECT_NE(msg.find(path), std::string::npos) << msg;
    EXPECT_NE(msg.find(c.want), std::string::npos) << msg;
  }
  const std::string junk = tmp("junk.pk3");
  write_bytes(junk, "PK\x03\x04 this is not really a zip archive");
  EXPECT_NE(error_of(junk).find("not a zip archive"), std::string::npos) << error_of(junk);
  // Central directory pointing outside the archive.
  std::string moved = zip({{"maps/a.bsp", test_map()}}, false);
  moved[moved.size() - 3] = '\x7f';  // high byte of the directory offset
  const std::string moved_path = tmp("moved.pk3");
  write_bytes(moved_path, moved);
  EXPECT_NE(error_of(moved_path).find("malformed zip archive"), std::string::npos) << error_of(moved_path);
}

// The reader's limits, each refused in one line naming the member before anything of its
// stated size is allocated: a deflate ratio no stream can reach (a zip bomb's claim), a
// member over 1 GiB, a compression method other than stored or deflate, encryption.
TEST(Quake3, Pk3MembersPastTheReadersLimitsAreRefused) {
  const std::string archive = zip({{"maps/a.bsp", test_map()}}, true);
  const size_t end = archive.size() - 22;
  uint32_t cd_at = 0;
  std::memcpy(&cd_at, archive.data() + end + 16, 4);
  auto patched = [&](size_t field, const std::string& bytes) {
    std::string z = archive;
    z.replace(cd_at + field, bytes.size(), bytes);
    return z;
  };
  auto le32 = [](uint32_t v) {
    std::string out;
    put(out, v);
    return out;
  };
  const struct {
    std::string bytes;
    const char* want;
  } cases[] = {{patched(24, le32(700u << 20)), "more than deflate can expand to"},
               {patched(24, le32(0xfffffff0u)), "claims 4294967280 bytes"},
               {patched(10, std::string("\x0c\x00", 2)), "unsupported compression method 12"},
               {patched(8, std::string("\x01\x00", 2)), "'maps/a.bsp' is encrypted"}};
  int k = 0;
  for (const auto& c : cases) {
    const std::string path = tmp("limit" + std::to_string(k++) + ".pk3");
    write_bytes(path, c.bytes);
    const std::string msg = error_of(path);
    EXPECT_NE(msg.find(path + ": malformed zip archive: "), std::string::npos) << msg;
    EXPECT_NE(msg.find(c.want), std::string::npos) << msg;
    EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
  }
}

// Truncation at every length and a corrupted byte at every offset: an error or a valid
// scene, never a crash or an out-of-bounds read (run under ASan). In memory: the same
// parser as for files, without thousands of file writes.
TEST(Quake3, TruncatedAndCorruptedFilesNeverCrash) {
  const std::string map = test_map();
  const std::string archive = zip({{"maps/test.bsp", map}}, true);
  size_t errors = 0, loaded = 0;
  auto attempt = [&](const std::string& bytes, bool is_pk3) {
    try {
      const Scene s = load_quake3_bytes(std::vector<uint8_t>(bytes.begin(), bytes.end()), "fuzz", is_pk3,
                                        SceneOptions{UpAxis::z});
      ++loaded;
      for (auto& v : s.vertices) ASSERT_TRUE(is_finite(v));
    } catch (const Error& e) {
      ++errors;
      ASSERT_EQ(std::string(e.what()).rfind("fuzz", 0), 0u) << e.what();
    }
  };
  for (size_t len = 0; len < archive.size(); ++len) attempt(archive.substr(0, len), true);
  EXPECT_EQ(loaded, 0u);  // every prefix loses the end record or part of the member
  for (size_t len = 0; len < map.size(); ++len) attempt(map.substr(0, len), false);
  EXPECT_EQ(loaded, 0u);
  for (size_t at = 0; at < archive.size(); ++at)
    for (uint8_t flip : {0x01, 0x5a, 0xff}) {
      std::string bad = archive;
      bad[at] = static_cast<char>(bad[at] ^ flip);
      attempt(bad, true);
    }
  for (size_t at = 0; at < map.size(); ++at)
    for (uint8_t flip : {0x01, 0x5a, 0xff}) {
      std::string bad = map;
      bad[at] = static_cast<char>(bad[at] ^ flip);
      attempt(bad, false);
    }
  EXPECT_GT(errors, archive.size() + map.size());
  EXPECT_GT(loaded, 0u);  // flips inside unused fields (uv, colour) still load
}

// One 65x65 patch control grid shared by `faces` faces: 1,024 blocks of 128 triangles
// each per face. 300 such faces (a 217 KB file) once made `bounds` take 4.6 GB.
std::string shared_patch_map(int faces) {
  std::vector<Vertex> v;
  for (int j = 0; j < 65; ++j)
    for (int i = 0; i < 65; ++i) v.push_back({{4.0 * i, 4.0 * j, 0.0}, {0, 0, 1}});
  std::vector<Face> f(size_t(faces), Face{0, 2, 0, 65 * 65, 0, 0, 65, 65});
  return bsp({{"textures/base/curve", 0}}, v, {}, f);
}

TEST(Quake3, TessellationPastTheCapIsRefusedBeforeAllocating) {
  // One such face is an ordinary big patch: it loads, with exactly the triangles counted.
  write_bytes(tmp("one_patch.bsp"), shared_patch_map(1));
  const Scene one = load_scene(tmp("one_patch.bsp"), SceneOptions{UpAxis::z});
  EXPECT_EQ(one.triangles.size(), 32u * 32 * 2 * kQuake3PatchLevel * kQuake3PatchLevel);
  // 300 faces ask for 39 million triangles: a one-line error naming the limit.
  const std::string big = shared_patch_map(300);
  EXPECT_LT(big.size(), 250u * 1024);
  write_bytes(tmp("shared_patch.bsp"), big);
  const std::string msg = error_of(tmp("shared_patch.bsp"), SceneOptions{UpAxis::z});
  EXPECT_NE(msg.find("too large"), std::string::npos) << msg;
  EXPECT_NE(msg.find(std::to_string(kQuake3MaxTriangles) + " triangles"), std::string::npos) << msg;
  // The same with polygon faces sharing one big mesh-vertex range.
  std::vector<Vertex> v;
  std::vector<int32_t> mv;
  for (int i = 0; i < 1000; ++i) v.push_back({{double(i), double(i % 7), double(i % 13)}, {0, 0, 1}});
  for (int t = 0; t < 999 * 3; ++t) mv.push_back(int32_t(t / 3 + t % 3 > 999 ? 0 : t / 3 + t % 3));
  std::vector<Face> faces(5000, Face{0, 3, 0, 1000, 0, int32_t(mv.size())});
  write_bytes(tmp("shared_mesh.bsp"), bsp({{"textures/base/wall", 0}}, v, mv, faces));
  const std::string msg2 = error_of(tmp("shared_mesh.bsp"), SceneOptions{UpAxis::z});
  EXPECT_NE(msg2.find("too large"), std::string::npos) << msg2;
}

// A member of 32 MiB that is not a map (32 KB deflated): refused on its first inflated
// bytes, before its stated size is allocated or the rest inflated.
TEST(Quake3, Pk3MemberIsCheckedForItsMagicBeforeItIsInflatedWhole) {
  const std::string zeros(size_t(32) << 20, '\0');
  write_bytes(tmp("zeros.pk3"), zip({{"maps/zeros.bsp", zeros}}, true));
  const auto t0 = std::chrono::steady_clock::now();
  const std::string msg = error_of(tmp("zeros.pk3"));
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_NE(msg.find("'maps/zeros.bsp' does not start with 'IBSP'"), std::string::npos) << msg;
  EXPECT_LT(s, 2.0);
}

}  // namespace scene_quake3_test
}  // namespace st
