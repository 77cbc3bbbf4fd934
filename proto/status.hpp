// Status: the result of every proto operation that can fail on bad input. Nothing in
// proto throws on bad bytes (exceptions never cross the library boundary, ARCHITECTURE.md "Errors, bad input, numbers"
// Embree anchor); only std::bad_alloc can escape, and never because of a length read
// off the wire (decoders cap every allocation by the bytes actually present).
#pragma once
#include <string>
#include <utility>

#include "proto/wire_format.hpp"

namespace st::proto {

struct Status {
  ErrorCode code = ErrorCode::ok;
  std::string detail;  // one line naming the message, field and byte offset; empty if ok

  bool ok() const { return code == ErrorCode::ok; }
  explicit operator bool() const { return ok(); }

  static Status success() { return {}; }
  static Status fail(ErrorCode c, std::string d) { return {c, std::move(d)}; }
};

// "payload_checksum: ..." (code name, then the detail).
std::string to_string(const Status& s);

}  // namespace st::proto
