// shadowtile: one executable, one subcommand per job (bounds, build, serve, load, ...).
#include <algorithm>
#include <cstdio>
#include <iostream>

#include "app/command.hpp"
#include "common/version.hpp"
#include "common/error.hpp"
#include "tiles/core/interval.hpp"

namespace st::cli {

std::vector<Command>& registry() {
  static std::vector<Command> commands;
  return commands;
}

}  // namespace st::cli

int main(int argc, char** argv) {
  using namespace st::cli;
  CLI::App app{
      "shadowtile: lossless compressed shadow maps, built offline and streamed as tiles.\n"
      "Exit codes: 0 ok, 1 error (bad input or I/O), 2 usage, 3 verification mismatch."};
  app.require_subcommand(1);
  app.set_version_flag("--version", std::string("shadowtile ") + st::kVersion);
  auto& cmds = registry();
  std::sort(cmds.begin(), cmds.end(), [](auto& a, auto& b) { return a.name < b.name; });
  for (auto& c : cmds) {
    CLI::App* sub = app.add_subcommand(c.name, c.description);
    c.setup(*sub);
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    int rc = app.exit(e);
    return rc == 0 ? 0 : kExitUsage;
  } catch (const ExitCode& e) {
    return e.code;
  } catch (const st::Error& e) {
    std::fprintf(stderr, "shadowtile: error: %s\n", e.what());
    return kExitError;
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "shadowtile: error: out of memory\n");
    return kExitError;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "shadowtile: error: %s\n", e.what());
    return kExitError;
  }
  return kExitOk;
}
