// Killed and resumed builds (pack_writer.hpp): a writer destroyed without finish() leaves
// "<name>.tmp"; resume keeps every complete cell, cuts a torn tail, and the finished pack
// is byte-identical to one built in one go.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "tests/tiles/interval_fields.hpp"
#include "tests/tiles/pack_test_support.hpp"
#include "common/error.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/core/pack_evaluator.hpp"
#include "tiles/core/pack_reader.hpp"
#include "tiles/encode/pack_writer.hpp"

namespace st {
namespace {

std::vector<uint8_t> slurp(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::vector<uint8_t>(std::istreambuf_iterator<char>(f), {});
}

struct ResumeSetup {
  IntervalTile field;
  CutParams cut;
  PackParams pack;
  std::vector<CutCell> cells;  // row-major
  CutGrid grid;
  Hierarchy h;
};

ResumeSetup make_setup(Encoding e) {
  ResumeSetup s;
  s.field = fields::city_field(64, 21);
  s.h = build_hierarchy(s.field);
  s.cut.map_level = 6;
  s.cut.skip_level = 2;
  s.cut.tile_bytes = 256;
  s.cut.codec = TileCodec::of(e);
  s.pack = PackParams::from(LightSpace::fit(LightSpec::parse("sun:azimuth=10,elevation=70"),
                                            Aabb{{0, 0, 0}, {1, 1, 1}}),
                            s.cut);
  s.pack.build_params = {{"scene", "city"}};
  s.grid = cut_hierarchy(s.h, s.cut, [&](CutCell&& c) { s.cells.push_back(std::move(c)); });
  return s;
}

void write_cells(PackWriter& w, const ResumeSetup& s, size_t begin, size_t end) {
  for (size_t i = begin; i < end; ++i)
    if (!w.is_done(s.cells[i].cx, s.cells[i].cy)) w.append_cell(s.cells[i]);
}

TEST(PackResume, KilledBuildsResumeToAnIdenticalPack) {
  for (Encoding e : packtest::available_encodings()) {
    ResumeSetup s = make_setup(e);
    std::string ref = packtest::temp_path("resume_ref.pack");
    {
      auto w = PackWriter::create(ref, s.pack);
      write_cells(*w, s, 0, s.cells.size());
      w->finish(s.grid);
    }
    const std::vector<uint8_t> want = slurp(ref);
    std::string path = packtest::temp_path("resume.pack");
    uint64_t journal_end_after_7 = 0;
    {
      auto w = PackWriter::create(path, s.pack);
      write_cells(*w, s, 0, 7);
      journal_end_after_7 = std::filesystem::file_size(w->tmp_path());
      write_cells(*w, s, 7, 9);
    }  // killed: no finish()
    ASSERT_TRUE(std::filesystem::exists(path + ".tmp"));
    ASSERT_FALSE(std::filesystem::exists(path));
    const uint64_t full = std::filesystem::file_size(path + ".tmp");
    // Tear the tail at every length inside cells 8 and 9: resume keeps 7 (or 8) cells.
    std::vector<uint8_t> tmp = slurp(path + ".tmp");
    const uint64_t step = fields::small_test_scale() ? 29 : 7;
    for (uint64_t cut_at = journal_end_after_7; cut_at <= full; cut_at += step) {
      {
        std::ofstream f(path + ".tmp", std::ios::binary | std::ios::trunc);
        f.write(reinterpret_cast<const char*>(tmp.data()), std::streamsize(cut_at));
      }
      auto w = PackWriter::resume(path, s.pack);
      ASSERT_GE(w->resumed_cells(), 7u) << cut_at;
      ASSERT_LE(w->resumed_cells(), 9u) << cut_at;
      EXPECT_EQ(w->cells().size(), w->resumed_cells());
      for (size_t i = 0; i < s.cells.size(); ++i)
        EXPECT_EQ(w->is_done(s.cells[i].cx, s.cells[i].cy), i < w->resumed_cells()) << cut_at << " cell " << i;
      write_cells(*w, s, 0, s.cells.size());
      w->finish(s.grid);
      ASSERT_EQ(slurp(path), want) << to_string(e) << " torn at " << cut_at;
      std::filesystem::remove(path);
    }
    // Garbage after the last record is cut off too.
    {
      auto w = PackWriter::create(path, s.pack);
      write_cells(*w, s, 0, 5);
    }
    {
      std::ofstream f(path + ".tmp", std::ios::binary | std::ios::app);
      f << "garbage that is not a record, long enough to look like one...";
    }
    auto w = PackWriter::create_or_resume(path, s.pack);
    EXPECT_EQ(w->resumed_cells(), 5u);
    EXPECT_GT(w->truncated_bytes(), 0u);
    write_cells(*w, s, 0, s.cells.size());
    w->finish(s.grid);
    EXPECT_EQ(slurp(path), want);
    auto reader = std::shared_ptr<PackReader>(PackReader::open(path));
    reader->verify(s.cut.codec.open);
    PackEvaluator ev(reader);
    EXPECT_EQ(packtest::first_difference(ev, s.h, packtest::exact_values(e) ? 6 : 2), "");
  }
}

TEST(PackResume, RefusesOtherParametersAndBadUse) {
  const auto encodings = packtest::available_encodings();
  ASSERT_FALSE(encodings.empty());
  ResumeSetup s = make_setup(encodings[0]);
  std::string path = packtest::temp_path("resume_params.pack");
  {
    auto w = PackWriter::create(path, s.pack);
    write_cells(*w, s, 0, 3);
    EXPECT_THROW(w->append_cell(s.cells[1]), Error);  // twice
    EXPECT_THROW(w->finish(s.grid), Error);           // cells missing
  }
  auto expect_refused = [&](PackParams p, const char* field) {
    try {
      PackWriter::resume(path, p);
      ADD_FAILURE() << field << " accepted";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
    }
  };
  PackParams p = s.pack;
  p.tile_bytes = 512;
  expect_refused(p, "tile_bytes");
  p = s.pack;
  p.scene_hash = 7;
  expect_refused(p, "scene hash");
  p = s.pack;
  p.build_params = {{"scene", "other"}};
  expect_refused(p, "build parameters");
  p = s.pack;
  p.light[3] += 1e-9;
  expect_refused(p, "light");
  // The unfinished .tmp is not a pack.
  EXPECT_THROW(PackReader::open(path + ".tmp"), FormatError);
  // A cell record whose grid entry disagrees is refused at finish.
  auto w = PackWriter::resume(path, s.pack);
  EXPECT_EQ(w->resumed_cells(), 3u);
  write_cells(*w, s, 0, s.cells.size());
  CutGrid other = s.grid;
  other.entries[0].value = 0.125f;
  EXPECT_THROW(w->finish(other), Error);
}

}  // namespace
}  // namespace st
