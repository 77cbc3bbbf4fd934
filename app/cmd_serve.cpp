// `shadowtile serve PACK_OR_DIR... --listen HOST:PORT ...`: the tile server in the
// all-in-one CLI; the same options as `shadowtile-server` (server/serve_command.hpp).
#include <memory>

#include "app/command.hpp"
#include "server/serve_command.hpp"

namespace st::cli {
namespace {

Register reg_serve{"serve", "Serve packs' tiles over TCP (the shadowtile wire protocol)", [](CLI::App& sub) {
  auto a = std::make_shared<server::ServeConfig>();
  server::add_serve_options(sub, *a);
  sub.callback([a] { server::run_serve(*a, "shadowtile serve"); });
}};

}  // namespace
}  // namespace st::cli
