// --scene-limits for every command that loads a scene file (tiles/bake/scene_limits.hpp).
#pragma once
#include <CLI/CLI.hpp>
#include <string>

namespace st::cli {

inline void add_scene_limits_option(CLI::App& sub, std::string& into) {
  sub.add_option("--scene-limits", into,
                 "What reading a scene file may cost, KEY=VALUE[,...]: memory=MIB (1024), seconds=S (50), "
                 "triangles=N (4194304, instances counted), texels=N (268435456, alpha textures together), "
                 "isolate=0|1 (1: read in a child process); 'none' lifts all but the child; 0 = unlimited "
                 "for memory and seconds");
}

}  // namespace st::cli
