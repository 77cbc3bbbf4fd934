// shadowtile-server: the tile server alone (what the server image ships). It links only
// common, proto, net, tiles/core and server: no Embree, assimp or OpenEXR. The options
// are those of `shadowtile serve` (server/serve_command.hpp).
// Exit codes: 0 stopped by a signal, 1 error (bad pack, bad option value, port in use),
// 2 usage.
#include <cstdio>
#include <exception>
#include <new>

#include "common/error.hpp"
#include "common/version.hpp"
#include "server/serve_command.hpp"

int main(int argc, char** argv) {
  CLI::App app{"shadowtile-server: serves packs' tiles over TCP (the shadowtile wire protocol)."};
  app.set_version_flag("--version", std::string("shadowtile-server ") + st::kVersion);
  st::server::ServeConfig config;
  st::server::add_serve_options(app, config);
  try {
    app.parse(argc, argv);
    st::server::run_serve(config, "shadowtile-server");
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? 0 : 2;
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "shadowtile-server: error: out of memory\n");
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "shadowtile-server: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
