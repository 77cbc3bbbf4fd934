// What Client::open, list_maps and server_stats throw: an st::Error (one line, as before)
// that also says why in a form code can branch on, so the C API (c_api.cpp) answers a
// status code without reading messages.
#pragma once
#include <cstdint>
#include <string>
#include <utility>

#include "common/error.hpp"
#include "proto/wire_format.hpp"

namespace st::client {

enum class CallFailure : uint8_t {
  bad_argument,       // a map name the protocol refuses before anything is sent
  stopped,            // the client is being destroyed
  refused,            // authentication failed, either way (final)
  timeout,            // no answer within request_timeout (connected or not)
  server_error,       // the server answered Error (server_code says which)
  unexpected_answer,  // an answer of the wrong type
};

class CallError : public Error {
 public:
  CallError(CallFailure kind, std::string what, proto::ErrorCode server_code = proto::ErrorCode::ok)
      : Error(std::move(what)), kind_(kind), server_code_(server_code) {}
  CallFailure kind() const noexcept { return kind_; }
  proto::ErrorCode server_code() const noexcept { return server_code_; }

 private:
  CallFailure kind_;
  proto::ErrorCode server_code_;
};

}  // namespace st::client
