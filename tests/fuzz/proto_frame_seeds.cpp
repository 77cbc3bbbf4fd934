// Seeds for proto_frame_fuzz.cpp (the proto module's harness; its input is a control
// byte then a byte stream): every message type as one frame, all of them back to back
// in one stream, and a stream split at odd chunk sizes. Control bit 7 set (repair the
// CRCs after mutation), receiver `any` (bits 5-6 = 2), chunk sizes from bits 0-4.
#include "tests/fuzz/seed_support.hpp"

std::vector<st::fuzz::Bytes> st::fuzz::seeds() {
  std::vector<Bytes> out;
  const std::vector<Bytes> frames = message_frames(3);
  Bytes all = {std::uint8_t(0x80 | 0x40 | 6)};
  for (std::size_t i = 0; i < frames.size(); ++i) {
    Bytes one = {std::uint8_t(0x80 | 0x40 | (i & 0x1f))};
    one.insert(one.end(), frames[i].begin(), frames[i].end());
    out.push_back(std::move(one));
    all.insert(all.end(), frames[i].begin(), frames[i].end());
  }
  out.push_back(all);
  // The same stream for a server's parser (it rejects server-only types part-way) and
  // a client's, with 1-byte and 32-byte chunks.
  for (std::uint8_t control : {std::uint8_t(0x80 | 0x00 | 0), std::uint8_t(0x80 | 0x20 | 31)}) {
    all[0] = control;
    out.push_back(all);
  }
  return out;
}
