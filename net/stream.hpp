// A byte stream for Asio coroutines that is either plain TCP or TLS over TCP (Asio's
// ssl::stream on OpenSSL), chosen at run time. Header-only: the client library uses it,
// and so does the server (server/connection.cpp) so both sides share one shape.
//
//   Stream s(std::move(socket), tls_context_or_null);
//   co_await s.handshake(ssl::stream_base::server, ec);  // no-op without TLS
//   n = co_await s.read_some(asio::buffer(buf), ec);
//   co_await s.write(buffers, ec);                       // whole, gathered
//   s.close();                                           // from the stream's executor
//
// With TLS, closing skips the close_notify exchange: the wire protocol frames every
// message, so a cut stream can never be mistaken for a complete answer.
#pragma once
#include <optional>

#include "net/asio.hpp"

#include <boost/asio/ssl.hpp>

namespace st::net {

// TLS 1.2 or later only, for both sides' contexts (the server's and the client's).
inline void allow_only_tls12_and_later(asio::ssl::context& ctx) {
  ctx.set_options(asio::ssl::context::default_workarounds | asio::ssl::context::no_sslv2 |
                  asio::ssl::context::no_sslv3 | asio::ssl::context::no_tlsv1 |
                  asio::ssl::context::no_tlsv1_1 | asio::ssl::context::single_dh_use);
}

class Stream {
 public:
  // `tls` null: plain TCP. Otherwise the context must outlive the stream.
  Stream(tcp::socket socket, asio::ssl::context* tls) {
    if (tls) tls_.emplace(std::move(socket), *tls);
    else plain_.emplace(std::move(socket));
  }

  bool tls() const { return tls_.has_value(); }
  tcp::socket& socket() { return tls_ ? tls_->next_layer() : *plain_; }
  auto get_executor() { return socket().get_executor(); }
  // The TLS object, e.g. for SNI and host-name verification before a client handshake.
  asio::ssl::stream<tcp::socket>* tls_stream() { return tls_ ? &*tls_ : nullptr; }

  asio::awaitable<void> handshake(asio::ssl::stream_base::handshake_type side, error_code& ec) {
    if (tls_) co_await tls_->async_handshake(side, asio::redirect_error(asio::use_awaitable, ec));
  }

  template <class MutableBuffers>
  asio::awaitable<size_t> read_some(const MutableBuffers& b, error_code& ec) {
    if (tls_) co_return co_await tls_->async_read_some(b, asio::redirect_error(asio::use_awaitable, ec));
    co_return co_await plain_->async_read_some(b, asio::redirect_error(asio::use_awaitable, ec));
  }

  template <class ConstBuffers>
  asio::awaitable<size_t> write(const ConstBuffers& b, error_code& ec) {
    if (tls_) co_return co_await asio::async_write(*tls_, b, asio::redirect_error(asio::use_awaitable, ec));
    co_return co_await asio::async_write(*plain_, b, asio::redirect_error(asio::use_awaitable, ec));
  }

  bool is_open() { return socket().is_open(); }

  void close() {
    error_code ignored;
    socket().shutdown(tcp::socket::shutdown_both, ignored);
    socket().close(ignored);
  }

 private:
  std::optional<tcp::socket> plain_;
  std::optional<asio::ssl::stream<tcp::socket>> tls_;
};

}  // namespace st::net
