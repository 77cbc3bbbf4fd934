// shadowtile wire protocol: the one public header (PROTOCOL.md is the spec).
//
// What is here: frame layout constants (wire_format.hpp), Status and error codes
// (status.hpp), limits + the in-flight tracker (limits.hpp), frame encoding and the
// incremental FrameParser (frame.hpp), the messages and their codecs (messages.hpp),
// map-name rules (names.hpp), handshake negotiation (handshake.hpp).
//
// Contracts, for all of it:
// - Pure encode/decode over byte spans: no sockets, no threads, no global state. Every
//   function is reentrant; a FrameParser or InFlight object belongs to one connection
//   and must not be used from two threads at once.
// - Nothing throws on bad bytes: failures come back as Status (a typed ErrorCode + one
//   line naming the message, field and byte offset). Only std::bad_alloc may escape.
// - Decoders are safe for untrusted input: every read is bounds-checked, truncation and
//   trailing bytes are rejected, lengths are checked against the negotiated Limits and
//   the bytes present before anything is allocated.
// - Outputs are appended to caller-owned std::vector<uint8_t>; decoded messages own
//   their bytes, except the *_view functions, whose spans borrow the input.
#pragma once

#include "proto/auth.hpp"
#include "proto/frame.hpp"
#include "proto/handshake.hpp"
#include "proto/limits.hpp"
#include "proto/messages.hpp"
#include "proto/names.hpp"
#include "proto/status.hpp"
#include "proto/wire_format.hpp"
