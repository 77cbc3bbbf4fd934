// libFuzzer harness for the zip reader (scene/scene_zip.hpp: minizip and our limits)
// that .pk3 archives go through. Input: byte 0 is a control byte (bit 0: list only members
// ending in ".bsp"), the rest the archive. list_zip must return nullopt, throw st::Error
// or return at most kZipMaxEntries entries whose packed bytes fit in the archive and whose
// size those bytes can give; extract_zip of each must throw st::Error or give exactly the
// size the entry states with a matching CRC-32.
#include <zlib.h>

#include "common/error.hpp"
#include "tests/fuzz/quake3_seeds.hpp"
#include "scene/scene_zip.hpp"

std::vector<st::fuzz::Bytes> st::fuzz::seeds() {
  std::vector<Bytes> out;
  const std::vector<Bytes> maps = quake3_maps(5);
  for (int deflated = 0; deflated < 2; ++deflated)
    for (size_t i = 0; i < 4; ++i) {
      std::vector<std::pair<std::string, Bytes>> files = {{"maps/m" + std::to_string(i) + ".bsp", maps[i]}};
      if (i % 2) files.push_back({"scripts/x.shader", Bytes(100 + 37 * i, uint8_t('a' + i))});
      if (i == 3) files.push_back({"MAPS/UPPER.BSP", Bytes{}});
      Bytes zip = zip_archive(files, deflated == 1);
      zip.insert(zip.begin(), uint8_t(i % 2));
      out.push_back(std::move(zip));
    }
  return out;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const std::vector<std::uint8_t> zip(data + 1, data + size);
  std::optional<std::vector<st::ZipEntry>> entries;
  try {
    entries = st::list_zip(zip, "fuzz.pk3", data[0] & 1 ? ".bsp" : "");
  } catch (const st::Error&) {
    return 0;
  }
  if (!entries) return 0;
  FUZZ_CHECK(entries->size() <= st::kZipMaxEntries);
  bool all = true;
  for (const st::ZipEntry& e : *entries) {
    FUZZ_CHECK(e.packed <= zip.size() && e.size <= (std::size_t(1) << 30));
    // What extract_zip allocates is bounded by the archive: stored bytes or deflate's
    // largest expansion of them.
    FUZZ_CHECK(e.method == 0 || e.method == 8);
    FUZZ_CHECK(e.method == 0 ? e.size == e.packed : e.size <= 1032 * e.packed + 64);
    try {
      const std::vector<std::uint8_t> bytes = st::extract_zip(zip, "fuzz.pk3", e);
      FUZZ_CHECK(bytes.size() == e.size);
      FUZZ_CHECK(uint32_t(crc32(0L, bytes.data(), uInt(bytes.size()))) == e.crc);
    } catch (const st::Error&) {
      all = false;
    }
  }
  if (all) st::fuzz::note_accepted();
  return 0;
}
