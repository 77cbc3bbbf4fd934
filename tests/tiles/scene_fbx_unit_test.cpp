// FBX units: a file's GlobalSettings UnitScaleFactor (centimetres per unit, which assimp
// reports and does not apply) scales its coordinates, so a file saved in metres (100) and
// the same file relabelled as centimetres (1) load 100x apart; the summary names the
// scale; a factor that is not a positive finite number is one line of error. Real files
// from the assimp test models (Debian assimp-testmodels).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "common/error.hpp"
#include "scene/scene.hpp"

namespace st {
namespace scene_fbx_unit_test {
namespace {

const std::string kModels = "/usr/share/assimp/models/FBX/";

std::string read_text(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// `path`'s ASCII FBX text with its UnitScaleFactor property set to `factor`, written to a
// temporary file.
std::string with_factor(const std::string& path, const std::string& factor, const std::string& name) {
  std::string text = read_text(path);
  const std::string key = "\"UnitScaleFactor\", \"double\", \"Number\", \"\",";
  const size_t at = text.find(key);
  if (at == std::string::npos) return "";
  const size_t from = at + key.size(), end = text.find_first_of("\r\n", from);
  text.replace(from, end - from, factor);
  const std::string out = (std::filesystem::temp_directory_path() / ("st_fbx_unit_" + name + ".fbx")).string();
  std::ofstream(out, std::ios::binary) << text;
  return out;
}

TEST(FbxUnit, MetresFileLoadsHundredTimesItsCentimetreTwin) {
  const std::string metres = kModels + "cubes_with_mirroring_and_pivot.fbx";  // UnitScaleFactor 100
  if (!std::filesystem::exists(metres)) GTEST_SKIP() << "assimp-testmodels not installed";
  const std::string cm = with_factor(metres, "1", "cm");
  ASSERT_FALSE(cm.empty()) << "no UnitScaleFactor property in " << metres;
  const Scene a = load_scene(metres), b = load_scene(cm);
  ASSERT_EQ(a.triangles.size(), b.triangles.size());
  ASSERT_GT(a.triangles.size(), 0u);
  const Aabb ba = a.bounds(), bb = b.bounds();
  const double tol = 1e-9 * std::max(1.0, 100 * (bb.hi - bb.lo).x);
  EXPECT_NEAR(ba.lo.x, 100 * bb.lo.x, tol);
  EXPECT_NEAR(ba.lo.y, 100 * bb.lo.y, tol);
  EXPECT_NEAR(ba.lo.z, 100 * bb.lo.z, tol);
  EXPECT_NEAR(ba.hi.x, 100 * bb.hi.x, tol);
  EXPECT_NEAR(ba.hi.y, 100 * bb.hi.y, tol);
  EXPECT_NEAR(ba.hi.z, 100 * bb.hi.z, tol);
  EXPECT_NE(summary(a).find("unit scale x100 "), std::string::npos) << summary(a);
  EXPECT_NE(summary(b).find("unit scale x1 "), std::string::npos) << summary(b);
  std::filesystem::remove(cm);
}

TEST(FbxUnit, BinaryFilesReportTheirFactor) {
  for (const auto& [file, scale] : {std::pair<const char*, const char*>{"global_settings.fbx", "x500 "},
                                    {"box.fbx", "x100 "}, {"spider.fbx", "x1 "}}) {
    const std::string path = kModels + file;
    if (!std::filesystem::exists(path)) GTEST_SKIP() << "assimp-testmodels not installed";
    const Scene s = load_scene(path);
    EXPECT_NE(summary(s).find(std::string("unit scale ") + scale), std::string::npos) << summary(s);
  }
}

TEST(FbxUnit, FactorThatIsNotPositiveIsOneLineOfError) {
  const std::string source = kModels + "cubes_with_names.fbx";
  if (!std::filesystem::exists(source)) GTEST_SKIP() << "assimp-testmodels not installed";
  for (const char* bad : {"-2", "0"}) {
    const std::string path = with_factor(source, bad, "bad");
    ASSERT_FALSE(path.empty());
    try {
      (void)load_scene(path);
      ADD_FAILURE() << "factor " << bad << " loaded";
    } catch (const Error& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find("UnitScaleFactor"), std::string::npos) << what;
      EXPECT_EQ(what.find('\n'), std::string::npos) << what;
    }
    std::filesystem::remove(path);
  }
}

}  // namespace
}  // namespace scene_fbx_unit_test
}  // namespace st
