// The options of every command that loads a scene file: --up (scene/scene.hpp
// parse_up_axis) and --scene-limits (scene/scene_limits.hpp).
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

// --up and --scene-limits; `when` prefixes --up's help (export: "With --deep: ").
inline void add_scene_file_options(CLI::App& sub, std::string& up, std::string& limits, const std::string& when = "") {
  sub.add_option("--up", up,
                 when + "Up axis of a scene file: y or z; default: the file's own (Quake 3: z; FBX metadata; "
                        "COLLADA <up_axis>), else y");
  add_scene_limits_option(sub, limits);
}

}  // namespace st::cli
