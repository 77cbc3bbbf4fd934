// How a command that connects to a server authenticates and encrypts: --key-file, --tls,
// --tls-ca, --tls-name, one wording for load, render and view.
#pragma once
#include <CLI/CLI.hpp>
#include <string>

#include "proto/auth.hpp"

namespace st::cli {

struct ConnectArgs {
  std::string key_file, tls_ca, tls_name;
  bool tls = false;
};

// `when` prefixes each help line (render: "With --server: ").
inline void add_connect_options(CLI::App& sub, ConnectArgs& into, const std::string& when = "") {
  sub.add_option("--key-file", into.key_file, when + "File holding the server's catalog key (hex or raw bytes)");
  sub.add_flag("--tls", into.tls, when + "Connect over TLS (the system's trust store unless --tls-ca)");
  sub.add_option("--tls-ca", into.tls_ca, when + "Trust this CA / self-signed certificate (PEM); implies --tls");
  sub.add_option("--tls-name", into.tls_name, when + "Name the server's certificate must carry (default: the host)");
}

// Into client::ClientOptions or loadgen::LoadOptions (the same four fields).
template <class Options>
void apply_connect_options(const ConnectArgs& a, Options& o) {
  if (!a.key_file.empty()) o.key = proto::load_key_file(a.key_file);
  o.tls = a.tls || !a.tls_ca.empty();
  o.tls_ca_file = a.tls_ca;
  o.tls_server_name = a.tls_name;
}

}  // namespace st::cli
