// Errors by layer (ARCHITECTURE.md "Errors, bad input, numbers"): `assert` for programmer contracts, ST_CHECK for data
// invariants that must hold in release builds, and st::Error (a one-line message naming
// the file/field at fault) for bad user input and I/O. Library code throws st::Error;
// only main() turns it into an exit code.
#pragma once
#include <stdexcept>
#include <string>

namespace st {

class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Thrown for bad or corrupt input data (scene files, packs, tiles, frames).
class FormatError : public Error {
 public:
  using Error::Error;
};

[[noreturn]] void check_failed(const char* expr, const char* file, int line);

}  // namespace st

#define ST_CHECK(expr) ((expr) ? (void)0 : ::st::check_failed(#expr, __FILE__, __LINE__))
