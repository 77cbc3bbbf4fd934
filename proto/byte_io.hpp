// Little-endian loads/stores and the bounded Reader/Writer the message codecs are built
// on (internal to proto and not installed). The Reader is the one place
// that touches untrusted payload bytes: every read is bounds-checked, the first failure
// is sticky and names the message, field and byte offset, and counts are checked against
// the bytes actually left before anything is allocated (meshoptimizer's decoders: never
// trust a length).
#pragma once
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include "common/bytes.hpp"
#include "proto/status.hpp"

namespace st::proto {

// The little-endian helpers are common/bytes.hpp's (one copy for every format).
using st::load_le;
using st::store_le;

// Appends to a byte vector. Encoders validate their content before writing, so the
// Writer itself cannot fail.
class Writer {
 public:
  explicit Writer(std::vector<std::uint8_t>& out) : out_(out) {}
  template <class T>
  void put(T v) {
    const std::size_t at = out_.size();
    out_.resize(at + sizeof(T));
    store_le<T>(out_.data() + at, v);
  }
  void u8(std::uint8_t v) { put(v); }
  void u16(std::uint16_t v) { put(v); }
  void u32(std::uint32_t v) { put(v); }
  void u64(std::uint64_t v) { put(v); }
  void bytes(std::span<const std::uint8_t> b) { out_.insert(out_.end(), b.begin(), b.end()); }
  void bytes(std::string_view s) { out_.insert(out_.end(), s.begin(), s.end()); }
  std::size_t size() const { return out_.size(); }

 private:
  std::vector<std::uint8_t>& out_;
};

class Reader {
 public:
  Reader(std::span<const std::uint8_t> bytes, const char* message)
      : bytes_(bytes), message_(message) {}

  bool ok() const { return status_.ok(); }
  std::size_t offset() const { return pos_; }
  std::size_t remaining() const { return bytes_.size() - pos_; }

  template <class T>
  bool get(T& v, const char* field) {
    if (!need(sizeof(T), field)) {
      v = 0;
      return false;
    }
    v = load_le<T>(bytes_.data() + pos_);
    pos_ += sizeof(T);
    return true;
  }
  bool u8(std::uint8_t& v, const char* f) { return get(v, f); }
  bool u16(std::uint16_t& v, const char* f) { return get(v, f); }
  bool u32(std::uint32_t& v, const char* f) { return get(v, f); }
  bool u64(std::uint64_t& v, const char* f) { return get(v, f); }

  // A view of the next n bytes (valid while the input is).
  bool view(std::size_t n, std::span<const std::uint8_t>& out, const char* field) {
    if (!need(n, field)) return false;
    out = bytes_.subspan(pos_, n);
    pos_ += n;
    return true;
  }
  bool copy(std::size_t n, std::vector<std::uint8_t>& out, const char* field) {
    std::span<const std::uint8_t> v;
    if (!view(n, v, field)) return false;
    out.assign(v.begin(), v.end());
    return true;
  }
  bool copy(std::size_t n, std::string& out, const char* field) {
    std::span<const std::uint8_t> v;
    if (!view(n, v, field)) return false;
    out.assign(reinterpret_cast<const char*>(v.data()), v.size());
    return true;
  }

  // A count of elements each at least min_elem_bytes long: fails with truncated if the
  // remaining bytes cannot possibly hold them, so callers may reserve(count) safely.
  bool count_fits(std::uint64_t count, std::size_t min_elem_bytes, const char* field) {
    if (!ok()) return false;
    if (min_elem_bytes != 0 && count > remaining() / min_elem_bytes) {
      return fail(ErrorCode::truncated, std::string(field) + " = " + std::to_string(count) +
                                            " needs " + std::to_string(count * min_elem_bytes) +
                                            " bytes, " + std::to_string(remaining()) + " left",
                  pos_);
    }
    return true;
  }

  // Records the first failure; `at` is the byte offset in the payload it refers to.
  bool fail(ErrorCode code, const std::string& what, std::size_t at) {
    if (ok())
      status_ = Status::fail(code, std::string(message_) + " payload byte " +
                                       std::to_string(at) + ": " + what);
    return false;
  }
  bool fail_field(ErrorCode code, const char* field, const std::string& what, std::size_t at) {
    return fail(code, std::string(field) + " " + what, at);
  }

  // Ends decoding: the first failure, or trailing_bytes if anything is left unread.
  Status finish() {
    if (ok() && pos_ != bytes_.size())
      fail(ErrorCode::trailing_bytes,
           std::to_string(bytes_.size() - pos_) + " bytes after the last field", pos_);
    return status_;
  }

 private:
  bool need(std::size_t n, const char* field) {
    if (!ok()) return false;
    if (n > remaining())
      return fail(ErrorCode::truncated,
                  std::string(field) + " needs " + std::to_string(n) + " bytes, " +
                      std::to_string(remaining()) + " left",
                  pos_);
    return true;
  }

  std::span<const std::uint8_t> bytes_;
  const char* message_;
  std::size_t pos_ = 0;
  Status status_;
};

}  // namespace st::proto
