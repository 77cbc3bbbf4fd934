// Hostile pack headers and grids a CRC does not catch (the attacker fixes the CRCs):
// non-finite or absurd lights, coarse levels outside the depth range or outside the
// intervals below them, and sparse files claiming gigabytes. Each must be a one-line
// st::FormatError when the pack is opened (or verified), before anything is traced,
// served, exported or allocated.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <unistd.h>

#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>

#include "common/bytes.hpp"
#include "common/error.hpp"
#include "common/text.hpp"
#include "tests/tiles/interval_fields.hpp"
#include "tests/tiles/pack_test_support.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/encode/pack_writer.hpp"
#include "tiles/core/pack_evaluator.hpp"
#include "tiles/core/pack_format.hpp"
#include "tiles/core/pack_reader.hpp"

namespace st {
namespace pack_hostile_test {

struct Built {
  IntervalTile field;
  std::vector<uint8_t> bytes;
};

// journal_records: the layout before feature payloads_only, whose cell records verify()
// checks the coarse levels against.
Built build_pack(const std::string& light, bool compress_grid = false, bool journal_records = false) {
  Built b{fields::city_field(32, 4), {}};
  CutParams cut;
  cut.map_level = 5;
  cut.skip_level = 2;
  cut.tile_bytes = 128;
  cut.codec = TileCodec::of(packtest::available_encodings().at(0));
  PackParams pp = PackParams::from(LightSpace::fit(LightSpec::parse(light), Aabb{{0, 0, 0}, {1, 1, 1}}), cut);
  pp.build_params = {{"scene", "hostile"}};
  pp.compress_grid = compress_grid;  // off: the tests below patch the grid section in place
  pp.journal_records = journal_records;
  const std::string path = packtest::temp_path("hostile.pack");
  write_pack(path, build_hierarchy(b.field), cut, pp);
  std::ifstream f(path, std::ios::binary);
  b.bytes.assign(std::istreambuf_iterator<char>(f), {});
  return b;
}

void fix_crc(std::vector<uint8_t>& b, size_t crc_at, uint64_t off, uint64_t size) {
  store_le<uint32_t>(b.data() + crc_at, crc32_of({b.data() + off, size_t(size)}));
}
void fix_header_crc(std::vector<uint8_t>& b) { fix_crc(b, 252, 0, 252); }

std::string open_error(std::vector<uint8_t> bytes, bool verify = false) {
  try {
    auto r = PackReader::open_memory(std::move(bytes), "hostile.pack");
    if (verify) r->verify();
  } catch (const FormatError& e) {
    EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << e.what();
    return e.what();
  }
  return "(opened)";
}

// The compressed grid section (tiles/PACK.md "Compressed grid section"): what every build
// writes; a wrong magic, an inflated size out of bounds or disagreeing with the stream, and
// a corrupt stream are refused in one line, every CRC right.
TEST(PackHostile, CompressedGridSectionIsCheckedBeforeItIsInflated) {
  const Built b = build_pack("sun:azimuth=30,elevation=50", true);
  ASSERT_EQ(open_error(b.bytes), "(opened)");
  const uint32_t flags = load_le<uint32_t>(b.bytes.data() + 20);
  ASSERT_TRUE(flags & kFeatureCompressedGrid);
  const uint64_t grid_at = load_le<uint64_t>(b.bytes.data() + 208), grid_size = load_le<uint64_t>(b.bytes.data() + 216);
  const auto reader = PackReader::open_memory(b.bytes, "hostile.pack");
  const uint32_t raw = uint32_t(reader->grid_bytes().size());
  EXPECT_EQ(load_le<uint32_t>(b.bytes.data() + grid_at), kCompressedGridMagic);
  EXPECT_EQ(load_le<uint32_t>(b.bytes.data() + grid_at + 4), raw);
  EXPECT_LT(grid_size, raw);  // the grid and preview deflate
  auto patched = [&](uint64_t at, uint32_t v) {
    std::vector<uint8_t> bytes = b.bytes;
    store_le<uint32_t>(bytes.data() + at, v);
    fix_crc(bytes, 244, grid_at, grid_size);
    fix_header_crc(bytes);
    return open_error(bytes);
  };
  EXPECT_NE(patched(grid_at, 0x12345678).find("compressed grid section: bad magic"), std::string::npos);
  EXPECT_NE(patched(grid_at + 4, 7).find("inflated size 7 outside"), std::string::npos);
  EXPECT_NE(patched(grid_at + 4, 0xFFFFFFF0u).find("outside"), std::string::npos);
  EXPECT_NE(patched(grid_at + 4, raw - 1).find("compressed grid section"), std::string::npos);
  EXPECT_NE(patched(grid_at + grid_size - 4, 0).find("compressed grid section"), std::string::npos);  // adler-32
  // Without the flag the same bytes are no raw grid section either.
  std::vector<uint8_t> bytes = b.bytes;
  store_le<uint32_t>(bytes.data() + 20, flags & ~uint32_t(kFeatureCompressedGrid));
  fix_header_crc(bytes);
  EXPECT_NE(open_error(bytes), "(opened)");
}

TEST(PackHostile, LightsNoBuildMakesAreRefusedAtOpen) {
  for (const char* light : {"sun:azimuth=30,elevation=50", "spot:pos=0.5,3,0.5,target=0.5,0,0.5,fov=60"}) {
    const Built b = build_pack(light);
    ASSERT_EQ(open_error(b.bytes), "(opened)");
    const double bad[] = {std::nan(""), INFINITY, -INFINITY, 1e308, -1e308};
    for (size_t slot = 0; slot < 18; ++slot)
      for (double v : bad) {
        std::vector<uint8_t> bytes = b.bytes;
        store_le<double>(bytes.data() + 40 + 8 * slot, v);
        fix_header_crc(bytes);
        const std::string msg = open_error(bytes);
        EXPECT_NE(msg.find("light"), std::string::npos) << light << " slot " << slot << " = " << v << ": " << msg;
      }
    // Finite but impossible: axes not unit, extent zero, far before near.
    for (auto [slot, v] : {std::pair{3, 2.0}, std::pair{12, 0.0}, std::pair{14, -1.0}}) {
      std::vector<uint8_t> bytes = b.bytes;
      store_le<double>(bytes.data() + 40 + 8 * slot, v);
      fix_header_crc(bytes);
      EXPECT_NE(open_error(bytes).find("light"), std::string::npos) << light << " slot " << slot;
    }
  }
}

// What `verify` and `export` ask (check_depth_range) and what verify() finds anyway.
std::string range_error(std::vector<uint8_t> bytes) {
  try {
    PackReader::open_memory(std::move(bytes), "hostile.pack")->check_depth_range();
  } catch (const FormatError& e) {
    return e.what();
  }
  return "(in range)";
}

TEST(PackHostile, CoarseValuesOutsideTheDepthRangeAreRefused) {
  const Built b = build_pack("sun:azimuth=30,elevation=50", false, true);
  ASSERT_EQ(range_error(b.bytes), "(in range)");
  const uint64_t grid_at = load_le<uint64_t>(b.bytes.data() + 208), grid_size = load_le<uint64_t>(b.bytes.data() + 216);
  const size_t coarse = CutGrid::coarse_count(2);
  for (float v : {-1000.0f, 1e30f, -INFINITY, INFINITY, -1e-7f, 1.0000001f}) {
    std::vector<uint8_t> bytes = b.bytes;
    for (size_t i = 0; i < coarse; ++i) store_le<float>(bytes.data() + grid_at + 8 + 4 * i, v);
    fix_crc(bytes, 244, grid_at, grid_size);
    fix_header_crc(bytes);
    EXPECT_EQ(open_error(bytes), "(opened)");  // the format carries any non-NaN float
    const std::string msg = range_error(bytes);
    EXPECT_NE(msg.find("outside the depth range"), std::string::npos) << v << ": " << msg;
    EXPECT_NE(open_error(bytes, true).find("hull of the intervals below"), std::string::npos) << v;
  }
  // An entry value out of range, likewise (verify: outside its cell's interval).
  std::vector<uint8_t> bytes = b.bytes;
  store_le<float>(bytes.data() + grid_at + 8 + 4 * coarse, -1000.0f);
  fix_crc(bytes, 244, grid_at, grid_size);
  fix_header_crc(bytes);
  EXPECT_NE(range_error(bytes).find("outside the depth range"), std::string::npos) << range_error(bytes);
  EXPECT_NE(open_error(bytes, true).find("disagreeing with the skip grid"), std::string::npos) << open_error(bytes, true);
}

TEST(PackHostile, CoarseValuesOutsideTheirCellsIntervalsFailVerify) {
  // Packs with journal records (old layout; payloads-only packs keep no intervals).
  const Built b = build_pack("sun:azimuth=30,elevation=50", false, true);
  float min_lo = INFINITY;
  for (const Interval& iv : b.field.data) min_lo = std::min(min_lo, iv.lo);
  ASSERT_GT(min_lo, 0.0f);  // so 0 lies below every interval of the map
  ASSERT_EQ(open_error(b.bytes, true), "(opened)");
  const uint64_t grid_at = load_le<uint64_t>(b.bytes.data() + 208), grid_size = load_le<uint64_t>(b.bytes.data() + 216);
  for (size_t i = 0; i < CutGrid::coarse_count(2); ++i) {
    std::vector<uint8_t> bytes = b.bytes;
    store_le<float>(bytes.data() + grid_at + 8 + 4 * i, 0.0f);
    fix_crc(bytes, 244, grid_at, grid_size);
    fix_header_crc(bytes);
    EXPECT_EQ(open_error(bytes), "(opened)");  // in range: open cannot tell
    const std::string msg = open_error(bytes, true);
    EXPECT_NE(msg.find("coarse value of level " + std::to_string(i == 0 ? 0 : 1)), std::string::npos) << i << ": " << msg;
  }
}

long max_rss_kib() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss;
}

// A sparse file whose header claims gigabytes (it takes a few KB on disk): refused
// without holding the claimed size in memory.
TEST(PackHostile, SparsePacksClaimingGigabytesAreRefusedWithoutAllocatingThem) {
  const Built b = build_pack("sun:azimuth=30,elevation=50", false, true);  // the plain index
  const uint64_t journal_at = load_le<uint64_t>(b.bytes.data() + 200), grid_at = load_le<uint64_t>(b.bytes.data() + 208);
  const uint64_t grid_size = load_le<uint64_t>(b.bytes.data() + 216);
  const uint64_t index_at = load_le<uint64_t>(b.bytes.data() + 224);
  const uint64_t two_gib = uint64_t(2) << 30, quarter_gib = uint64_t(1) << 28;
  const long rss_before = max_rss_kib();
  auto write_sparse = [&](const std::string& name, const std::vector<uint8_t>& head, uint64_t tail_at,
                          const std::vector<uint8_t>& tail, uint64_t size) {
    const std::string path = packtest::temp_path(name);
    {
      std::ofstream f(path, std::ios::binary | std::ios::trunc);
      f.write(reinterpret_cast<const char*>(head.data()), std::streamsize(head.size()));
      f.seekp(std::streamoff(tail_at));
      f.write(reinterpret_cast<const char*>(tail.data()), std::streamsize(tail.size()));
    }
    std::filesystem::resize_file(path, size);
    return path;
  };
  // 1. The index claims ~2 GiB of entries: more tiles than the journal has room for.
  {
    std::vector<uint8_t> bytes = b.bytes;
    const uint64_t tiles = (two_gib - index_at) / kIndexEntryBytes;
    store_le<uint64_t>(bytes.data() + 232, tiles);
    fix_header_crc(bytes);
    const std::string path = write_sparse("sparse_index.pack", bytes, bytes.size(), {}, index_at + tiles * kIndexEntryBytes);
    try {
      PackReader::open(path);
      ADD_FAILURE() << "opened";
    } catch (const FormatError& e) {
      EXPECT_NE(std::string(e.what()).find("cannot fit a journal"), std::string::npos) << e.what();
    }
    std::filesystem::remove(path);
  }
  // 2. Journal and index both 256 MiB of holes: the index CRC fails, read in chunks.
  {
    std::vector<uint8_t> head(b.bytes.begin(), b.bytes.begin() + long(grid_at));
    const std::vector<uint8_t> grid(b.bytes.begin() + long(grid_at), b.bytes.begin() + long(grid_at + grid_size));
    const uint64_t new_grid = quarter_gib, new_index = new_grid + grid_size;
    const uint64_t tiles = std::min((two_gib - new_index) / kIndexEntryBytes, (new_grid - journal_at) / kRecordBytes);
    store_le<uint64_t>(head.data() + 208, new_grid);
    store_le<uint64_t>(head.data() + 224, new_index);
    store_le<uint64_t>(head.data() + 232, tiles);
    fix_header_crc(head);
    const std::string path = write_sparse("sparse_journal.pack", head, new_grid, grid, new_index + tiles * kIndexEntryBytes);
    try {
      PackReader::open(path);
      ADD_FAILURE() << "opened";
    } catch (const FormatError& e) {
      EXPECT_NE(std::string(e.what()).find("tile index CRC mismatch"), std::string::npos) << e.what();
    }
    std::filesystem::remove(path);
  }
  // 3. A payloads-only pack whose compact index claims a 256 MiB stream of holes: the CRC,
  // read in chunks, fails before anything that size is held.
  {
    const Built c = build_pack("sun:azimuth=30,elevation=50");
    const uint64_t at = load_le<uint64_t>(c.bytes.data() + 224);
    ASSERT_TRUE(load_le<uint32_t>(c.bytes.data() + 20) & kFeaturePayloadsOnly);
    std::vector<uint8_t> head(c.bytes.begin(), c.bytes.begin() + long(at + kCompactIndexHeaderBytes));
    store_le<uint32_t>(head.data() + at + 4, uint32_t(quarter_gib - 1));
    const std::string path = write_sparse("sparse_compact.pack", head, head.size(), {}, at + 8 + quarter_gib - 1);
    try {
      PackReader::open(path);
      ADD_FAILURE() << "opened";
    } catch (const FormatError& e) {
      EXPECT_NE(std::string(e.what()).find("tile index CRC mismatch"), std::string::npos) << e.what();
    }
    std::filesystem::remove(path);
  }
  EXPECT_LT(max_rss_kib() - rss_before, 128 * 1024) << "KiB of peak RSS grown";
}

// Build parameters are text from the file: inspect and summary() escape them.
TEST(PackHostile, PrintableTextEscapesControlsLikeJson) {
  EXPECT_EQ(printable_text("city size=3 ünïcode"), "city size=3 ünïcode");
  EXPECT_EQ(printable_text("a\x1b[2Jb\rc\\d"), "a\\u001b[2Jb\\rc\\\\d");
  EXPECT_EQ(printable_text(std::string("\x00\x7f", 2)), "\\u0000\\u007f");
  EXPECT_EQ(printable_text("\xc2\x9b" "31m"), "\\u009b31m");           // C1 CSI
  EXPECT_EQ(printable_text("\xff\xc3"), "\\xff\\xc3");                 // not UTF-8
  EXPECT_EQ(printable_text("\xed\xa0\x80"), "\\xed\\xa0\\x80");        // a surrogate
  EXPECT_EQ(printable_text("\xe2\x82\xac"), "\xe2\x82\xac");           // the euro sign
}

}  // namespace pack_hostile_test
}  // namespace st
