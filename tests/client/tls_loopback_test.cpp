// TLS over loopback (net/stream.hpp; server --tls-cert/--tls-key, client tls options):
// tiles arrive bit-exactly through TLS, together with the key proof; a client that does
// not trust the certificate, expects another name, or speaks plain TCP to a TLS server
// (or TLS to a plain one) gets nothing; bad certificate files are clear errors. The
// certificates are made here with OpenSSL (self-signed P-256, SAN localhost/127.0.0.1).
#include <gtest/gtest.h>

#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/x509.h>
#include <openssl/x509v3.h>

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>

#include "client/map_access.hpp"
#include "proto/proto.hpp"
#include "server/handshake_limiter.hpp"
#include "tests/client/loopback.hpp"

namespace st::client {
namespace {

using namespace std::chrono_literals;
using looptest::build_pack;
using looptest::RawSocket;
using looptest::read_frame;
using looptest::start_server;
using looptest::wait_until;

struct CertFiles {
  std::string cert, key;
};

// A self-signed certificate for `names` (DNS:localhost, IP:127.0.0.1), written as PEM.
CertFiles make_cert(const std::string& stem) {
  const std::filesystem::path dir(SHADOWTILE_TEST_TMP);
  CertFiles f{(dir / (stem + ".crt")).string(), (dir / (stem + ".key")).string()};
  std::unique_ptr<EVP_PKEY, decltype(&EVP_PKEY_free)> pkey(EVP_EC_gen("P-256"), EVP_PKEY_free);
  ST_CHECK(pkey);
  std::unique_ptr<X509, decltype(&X509_free)> x(X509_new(), X509_free);
  ST_CHECK(x);
  X509_set_version(x.get(), 2);
  ASN1_INTEGER_set(X509_get_serialNumber(x.get()), 1);
  X509_gmtime_adj(X509_getm_notBefore(x.get()), -3600);
  X509_gmtime_adj(X509_getm_notAfter(x.get()), 3600L * 24);
  X509_set_pubkey(x.get(), pkey.get());
  X509_NAME* name = X509_get_subject_name(x.get());
  X509_NAME_add_entry_by_txt(name, "CN", MBSTRING_ASC, reinterpret_cast<const unsigned char*>("localhost"), -1, -1, 0);
  X509_set_issuer_name(x.get(), name);
  X509V3_CTX ctx;
  X509V3_set_ctx_nodb(&ctx);
  X509V3_set_ctx(&ctx, x.get(), x.get(), nullptr, nullptr, 0);
  for (auto [nid, value] : {std::pair{NID_subject_alt_name, "DNS:localhost,IP:127.0.0.1"},
                            std::pair{NID_basic_constraints, "critical,CA:TRUE"}}) {
    X509_EXTENSION* ext = X509V3_EXT_conf_nid(nullptr, &ctx, nid, value);
    ST_CHECK(ext);
    X509_add_ext(x.get(), ext, -1);
    X509_EXTENSION_free(ext);
  }
  ST_CHECK(X509_sign(x.get(), pkey.get(), EVP_sha256()) > 0);
  FILE* c = std::fopen(f.cert.c_str(), "w");
  FILE* k = std::fopen(f.key.c_str(), "w");
  ST_CHECK(c && k);
  PEM_write_X509(c, x.get());
  PEM_write_PrivateKey(k, pkey.get(), nullptr, nullptr, 0, nullptr, nullptr);
  std::fclose(c);
  std::fclose(k);
  return f;
}

ClientOptions tls_options(const std::string& ca, const std::string& name = "localhost") {
  ClientOptions o = looptest::quick_options();
  o.request_timeout = looptest::small_scale() ? 4s : 2s;  // failures below wait this long
  o.tls = true;
  o.tls_ca_file = ca;
  o.tls_server_name = name;
  return o;
}

server::ServerOptions tls_server(const CertFiles& c) {
  server::ServerOptions o;
  o.tls_cert_file = c.cert;
  o.tls_key_file = c.key;
  return o;
}

uint32_t bits(float f) {
  uint32_t u;
  std::memcpy(&u, &f, 4);
  return u;
}

TEST(TlsLoopback, TilesAndTheKeyProofTravelThroughTlsBitExactly) {
  const CertFiles cert = make_cert("server");
  auto p = build_pack("tlsmap", 6, 71, looptest::available_encodings()[0], 3, 1024);
  server::ServerOptions so = tls_server(cert);
  so.key = std::vector<uint8_t>(32, 0x5c);
  auto srv = start_server({p.path}, so);
  ClientOptions o = tls_options(cert.cert);
  o.request_timeout = 20s;
  o.key = so.key;
  Client c({"127.0.0.1", srv.port}, o);
  Map m = c.open("tlsmap");
  ASSERT_TRUE(wait_until([&] {
    m.request_region(6, 0, 0, 64, 64, 1);
    return m.region_resident(6, 0, 0, 64, 64);
  }));
  PackEvaluator local(p.reader);
  for (uint32_t level = 0; level <= 6; ++level)
    for (uint64_t y = 0; y < (1u << level); ++y)
      for (uint64_t x = 0; x < (1u << level); ++x)
        ASSERT_EQ(bits(m.depth(level, x, y)), bits(local.depth(level, x, y)));
  // The name check also accepts the IP address the certificate carries.
  ClientOptions by_ip = tls_options(cert.cert, "");
  by_ip.key = so.key;
  by_ip.request_timeout = 20s;
  Client c2({"127.0.0.1", srv.port}, by_ip);
  EXPECT_EQ(c2.list_maps().size(), 1u);
}

TEST(TlsLoopback, UntrustedOrMisnamedCertificatesAndPlainPeersGetNothing) {
  const CertFiles cert = make_cert("server2"), other = make_cert("other");
  auto p = build_pack("tlsmap2", 5, 72, looptest::available_encodings()[0], 2, 1024);
  auto srv = start_server({p.path}, tls_server(cert));
  {  // Trusts another CA.
    Client c({"127.0.0.1", srv.port}, tls_options(other.cert));
    try {
      c.open("tlsmap2");
      ADD_FAILURE() << "opened through an untrusted certificate";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("TLS handshake"), std::string::npos) << e.what();
    }
    EXPECT_EQ(c.stats().connects, 0u);
  }
  {  // Trusts the CA but expects another name.
    Client c({"127.0.0.1", srv.port}, tls_options(cert.cert, "tiles.example.com"));
    EXPECT_THROW(c.open("tlsmap2"), Error);
    EXPECT_EQ(c.stats().connects, 0u);
  }
  {  // Plain TCP to the TLS port: the Hello is not a TLS ClientHello; no answer, closed.
    RawSocket s(srv.port);
    ASSERT_TRUE(s.send(looptest::hello_frame()));
    EXPECT_FALSE(read_frame(s).ok);
    EXPECT_TRUE(s.wait_closed());
  }
  {  // TLS to a plain server.
    auto plain = start_server({p.path});
    Client c({"127.0.0.1", plain.port}, tls_options(cert.cert));
    EXPECT_THROW(c.open("tlsmap2"), Error);
    EXPECT_EQ(c.stats().connects, 0u);
  }
  // The TLS server kept serving: a trusting client gets in.
  ClientOptions ok = tls_options(cert.cert);
  ok.request_timeout = 20s;
  Client good({"127.0.0.1", srv.port}, ok);
  EXPECT_EQ(good.list_maps().size(), 1u);
}

TEST(TlsLoopback, BadCertificateFilesAreClearErrors) {
  const CertFiles cert = make_cert("server3"), other = make_cert("other3");
  auto p = build_pack("tlsmap3", 4, 73, looptest::available_encodings()[0], 2, 1024);
  auto catalog = [&] { return server::Catalog::scan(std::vector<std::string>{p.path}); };
  auto error_of = [&](server::ServerOptions o) -> std::string {
    try {
      server::Server s(catalog(), o);
    } catch (const Error& e) {
      return e.what();
    }
    return "";
  };
  server::ServerOptions o = tls_server(cert);
  o.tls_key_file = other.key;  // not the certificate's key
  EXPECT_NE(error_of(o).find(other.key), std::string::npos) << error_of(o);  // names the key file
  o = tls_server(cert);
  o.tls_cert_file = "/nonexistent/server.crt";
  EXPECT_NE(error_of(o).find("/nonexistent/server.crt"), std::string::npos) << error_of(o);
  o = tls_server(cert);
  o.tls_key_file.clear();
  EXPECT_NE(error_of(o).find("both"), std::string::npos);
  ClientOptions co = tls_options("/nonexistent/ca.pem");
  EXPECT_THROW(Client({"127.0.0.1", 1}, co), Error);
}

// The TLS handshake limiter (server/handshake_limiter.hpp): one network opening
// connections as fast as it can gets its burst, then the rest are closed before any
// handshake work (counted as rejected); a client on another network is served meanwhile.
TEST(TlsLoopback, HandshakeFloodFromOneNetworkIsRateLimited) {
  const CertFiles cert = make_cert("limited");
  auto p = build_pack("tlsmap4", 5, 74, looptest::available_encodings()[0], 2, 1024);
  server::ServerOptions so = tls_server(cert);
  so.tls_handshakes_per_second = 2;
  so.tls_handshake_burst = 3;
  auto srv = start_server({p.path}, so);
  std::vector<std::unique_ptr<RawSocket>> flood;
  for (int i = 0; i < 12; ++i) flood.push_back(std::make_unique<RawSocket>(srv.port, 300ms, "127.0.71.2"));
  ASSERT_TRUE(wait_until([&] { return srv.server->stats().connections_rejected >= 8; }, 5s))
      << srv.server->stats().connections_rejected;
  size_t closed = 0;
  for (auto& s : flood) closed += s->wait_closed();
  EXPECT_GE(closed, 8u);
  EXPECT_LE(closed, 10u);  // the burst (3, plus what refilled meanwhile) was let in
  Client c({"127.0.0.1", srv.port}, tls_options(cert.cert));
  EXPECT_EQ(c.list_maps().size(), 1u);
  // A unit check of the bucket: 3 at once, then 2 a second.
  server::HandshakeLimiter lim(2, 3);
  const auto t0 = std::chrono::steady_clock::now();
  const server::HandshakeLimiter::Prefix a{1}, b{2};
  int in = 0;
  for (int i = 0; i < 10; ++i) in += lim.admit(a, t0);
  EXPECT_EQ(in, 3);
  EXPECT_TRUE(lim.admit(b, t0));
  EXPECT_FALSE(lim.admit(a, t0 + 400ms));
  EXPECT_TRUE(lim.admit(a, t0 + 600ms));
}

}  // namespace
}  // namespace st::client
