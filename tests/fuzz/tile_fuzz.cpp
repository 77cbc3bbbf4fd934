// libFuzzer harness for one tile decoder, chosen at compile time by ST_FUZZ_ENCODING
// (mh, mmh, dagmh or vsdag; tests/fuzz/CMakeLists.txt builds one executable per encoding).
// Input: the encoded tile buffer, exactly as it lies in a pack (after decompression).
// Contract (encoding.hpp): the opener validates the whole buffer or throws
// st::FormatError; a buffer it accepts must then answer every lookup without reading
// out of bounds (evaluator_probe.hpp probes every level and PCF kernels). A re-encoding
// is not compared: hostile buffers need not be canonical.
#include <span>

#include "tests/fuzz/evaluator_probe.hpp"
#include "tests/fuzz/seed_support.hpp"
#include "tiles/core/encoding.hpp"
#include "common/error.hpp"

#ifndef ST_FUZZ_ENCODING
#error "define ST_FUZZ_ENCODING to mh, mmh, dagmh or vsdag"
#endif
#define ST_FUZZ_STR2(x) #x
#define ST_FUZZ_STR(x) ST_FUZZ_STR2(x)

namespace {

const st::Encoding kEncoding = st::parse_encoding(ST_FUZZ_STR(ST_FUZZ_ENCODING));

}  // namespace

std::vector<st::fuzz::Bytes> st::fuzz::seeds() {
  // Levels 0..5: 24 tiles of a few bytes to a few KiB per seed number.
  std::vector<Bytes> out = encoded_tiles(kEncoding, 5, 1);
  for (Bytes& b : encoded_tiles(kEncoding, 3, 2)) out.push_back(std::move(b));
  return out;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  // The opener borrows the bytes: an exact-size heap copy, so ASan sees a read one past
  // the end (libFuzzer's own buffer is exact too; the replay driver's may not be).
  const std::vector<std::uint8_t> bytes(data, data + size);
  std::unique_ptr<st::Evaluator> ev;
  try {
    ev = st::open_encoded(kEncoding, std::span<const std::uint8_t>(bytes.data(), bytes.size()));
  } catch (const st::FormatError&) {
    return 0;  // rejected: the documented outcome for a bad buffer
  }
  FUZZ_CHECK(ev != nullptr);
  st::fuzz::note_accepted();
  st::fuzz::probe_evaluator(*ev, st::fuzz::input_hash(data, size));
  return 0;
}
