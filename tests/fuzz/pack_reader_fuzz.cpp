// libFuzzer harness for the pack reader (pack_reader.hpp) and PackEvaluator. Input: a
// whole pack file. Flow: PackReader::open_memory; for the first tiles of the index
// read_raw (CRC, zlib, size checks), open encoded tiles with the pack's encoding and
// probe them, parse index tiles with read_index_tile; verify() with the real opener;
// then a PackEvaluator answers lookups at every level and PCF (evaluator_probe.hpp).
// Every rejection must be an st::FormatError (the reader's documented error for corrupt
// data); anything else escaping, a crash or a sanitizer report is a finding.
#include <span>

#include "tests/fuzz/evaluator_probe.hpp"
#include "tests/fuzz/seed_support.hpp"
#include "tiles/core/encoding.hpp"
#include "tiles/core/error.hpp"
#include "tiles/core/pack_evaluator.hpp"
#include "tiles/core/pack_reader.hpp"

std::vector<st::fuzz::Bytes> st::fuzz::seeds() { return pack_files(11); }

namespace {

constexpr size_t kMaxTilesProbed = 8;

void probe_tiles(const st::PackReader& reader, uint64_t hash) {
  size_t n = 0;
  for (const st::TileIndexEntry& t : reader.tiles()) {
    if (n++ == kMaxTilesProbed) break;
    try {
      if (t.kind == st::TileKind::encoded) {
        const std::vector<uint8_t> raw = reader.read_raw(t.id);
        FUZZ_CHECK(raw.size() == t.raw_size);
        auto ev = st::open_encoded(reader.encoding(), raw);
        st::fuzz::probe_evaluator(*ev, hash, 8);
      } else {
        // The parent entry is not at hand here: try each depth an index tile may have
        // (the PackEvaluator below reaches them through their real parents).
        for (uint8_t d = 1; d <= st::kMaxIndexLevels; ++d) {
          try {
            const st::CutGrid g =
                reader.read_index_tile(t.id, st::GridEntry{0.0f, st::EntryKind::index, d});
            FUZZ_CHECK(g.levels == d);
          } catch (const st::FormatError&) {
          }
        }
      }
    } catch (const st::FormatError&) {
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::shared_ptr<const st::PackReader> reader;
  try {
    reader = st::PackReader::open_memory(std::vector<std::uint8_t>(data, data + size), "fuzz.pack");
  } catch (const st::FormatError&) {
    return 0;
  }
  FUZZ_CHECK(reader->map_level() <= st::kMaxLevel);
  FUZZ_CHECK(reader->skip_level() <= reader->map_level());
  FUZZ_CHECK(reader->grid().levels == reader->skip_level());
  const uint64_t hash = st::fuzz::input_hash(data, size);
  probe_tiles(*reader, hash);
  bool verified = true;
  try {
    reader->verify([&](std::span<const uint8_t> b) { return st::open_encoded(reader->encoding(), b); });
  } catch (const st::FormatError&) {
    verified = false;
  }
  if (verified) st::fuzz::note_accepted();
  try {
    st::PackEvaluator ev(reader, 4);
    st::fuzz::probe_evaluator(ev, hash);
  } catch (const st::FormatError&) {
    // A pack that verify() accepted must answer every lookup.
    FUZZ_CHECK(!verified);
  }
  return 0;
}
