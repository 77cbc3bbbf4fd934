// What every harness under tests/fuzz/ provides, and what the two drivers need from it.
//
// A harness is one .cpp file defining LLVMFuzzerTestOneInput (the libFuzzer entry point)
// plus one *_seeds.cpp (or the same file) defining st::fuzz::seeds(): valid inputs made
// by the real encoders (build_hierarchy + encode, write_pack, encode_message), so the
// fuzzer starts past the magic numbers and CRCs. Both are linked into
//   - <name>            libFuzzer executable (clang, SHADOWTILE_FUZZ=ON; scripts/fuzz);
//   - <name>_replay     replay_main.cpp: the seeds plus deterministic mutations, or given
//                       files (crash reproduction); built by every toolchain and run by
//                       ctest, so each harness also runs under g++ and the asan preset.
// Harness checks go beyond "no crash": a property that fails calls fuzz_fail(), which
// prints the reason and aborts (libFuzzer and the replay driver both report the input).
#pragma once
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);

namespace st::fuzz {

using Bytes = std::vector<std::uint8_t>;

// Valid inputs for this harness (a few dozen, each well under the harness's max_len).
std::vector<Bytes> seeds();

// Inputs the decoder under test accepted (the harness calls note_accepted()). The
// replay driver requires every seed to be accepted, so a harness whose seeds stopped
// reaching past the first check fails ctest instead of silently fuzzing nothing.
inline std::size_t accepted_inputs = 0;
inline void note_accepted() { ++accepted_inputs; }

[[noreturn]] inline void fuzz_fail(const char* what, const char* file, int line) {
  std::fprintf(stderr, "fuzz property failed: %s (%s:%d)\n", what, file, line);
  std::fflush(stderr);
  std::abort();
}

}  // namespace st::fuzz

// Aborts (a finding) when a harness property does not hold.
#define FUZZ_CHECK(expr) ((expr) ? (void)0 : ::st::fuzz::fuzz_fail(#expr, __FILE__, __LINE__))
