// Subcommand registry of the `shadowtile` executable. Each cmd_*.cpp registers itself:
//   static st::cli::Register reg{"bounds", "Trace dual depth bounds", setup_fn};
// where setup_fn(CLI::App& sub) adds options and sets sub.callback(...). A callback
// signals failure by throwing st::Error (exit code 1, one-line message) or by calling
// cli::exit_with(code).
#pragma once
#include <CLI/CLI.hpp>
#include <functional>
#include <string>
#include <vector>

#include "tiles/core/resolution.hpp"

namespace st::cli {

// Exit codes (meaningful, documented in --help): 0 ok, 1 error (bad input, I/O),
// 2 usage error, 3 verification found mismatches, 130 interrupted.
inline constexpr int kExitOk = 0, kExitError = 1, kExitUsage = 2, kExitMismatch = 3,
                     kExitInterrupted = 130;

struct Command {
  std::string name, description;
  std::function<void(CLI::App&)> setup;
};

std::vector<Command>& registry();

struct Register {
  Register(std::string name, std::string description, std::function<void(CLI::App&)> setup) {
    registry().push_back({std::move(name), std::move(description), std::move(setup)});
  }
};

// Thrown by a callback to exit with a specific code after printing nothing more.
struct ExitCode {
  int code;
};
[[noreturn]] inline void exit_with(int code) { throw ExitCode{code}; }

using st::parse_resolution;  // tiles/core/resolution.hpp

}  // namespace st::cli
