// libFuzzer harness for DAG-MH tiles that reference a pack dictionary (tiles/core/DAGMH.md
// "Dictionary"). Input: u32 n (little-endian), then n bytes of dictionary, then the tile.
// Contract: Dictionary::open validates the dictionary or throws st::FormatError; then
// open_dagmh(tile, dictionary) validates the tile against it or throws; an accepted pair
// answers every lookup without reading out of bounds (evaluator_probe.hpp).
#include <cstring>
#include <span>

#include "common/bytes.hpp"
#include "common/error.hpp"
#include "tests/fuzz/evaluator_probe.hpp"
#include "tests/fuzz/seed_support.hpp"
#include "tiles/encode/dagmh_dictionary.hpp"
#include "tiles/core/dagmh_validate.hpp"

std::vector<st::fuzz::Bytes> st::fuzz::seeds() {
  // The seed tiles of two seed numbers share topologies (the same field kinds and sizes):
  // one dictionary over all of them, each rewritten tile with it.
  std::vector<std::vector<uint8_t>> tiles;
  for (uint64_t seed : {1, 2})
    for (Bytes& b : encoded_tiles(Encoding::dagmh, 5, seed)) tiles.push_back(std::move(b));
  const auto shared = dagmh::share_across_tiles(tiles);
  std::vector<Bytes> out;
  for (const auto& t : shared.tiles) {
    Bytes in(4);
    st::store_le<uint32_t>(in.data(), uint32_t(shared.dictionary.size()));
    in.insert(in.end(), shared.dictionary.begin(), shared.dictionary.end());
    in.insert(in.end(), t.begin(), t.end());
    out.push_back(std::move(in));
  }
  return out;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 4) return 0;
  const uint32_t n = st::load_le<uint32_t>(data);
  if (n > size - 4) return 0;
  // Exact-size heap copies, so ASan sees a read one past the end of either.
  std::vector<std::uint8_t> dict_bytes(data + 4, data + 4 + n);
  const std::vector<std::uint8_t> tile(data + 4 + n, data + size);
  std::shared_ptr<const st::dagmh::Dictionary> dict;
  std::unique_ptr<st::Evaluator> ev;
  try {
    dict = st::dagmh::Dictionary::open(std::move(dict_bytes));
    ev = st::open_dagmh(std::span<const std::uint8_t>(tile.data(), tile.size()), dict);
  } catch (const st::FormatError&) {
    return 0;  // rejected: the documented outcome for a bad buffer
  }
  FUZZ_CHECK(ev != nullptr);
  st::fuzz::note_accepted();
  st::fuzz::probe_evaluator(*ev, st::fuzz::input_hash(data, size));
  return 0;
}
