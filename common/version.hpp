// The one version string of shadowtile. CMakeLists.txt reads it from here for
// project(VERSION) and the installed package's version file; `--version` prints it.
#pragma once

namespace st {
inline constexpr const char* kVersion = "0.2.0";
}  // namespace st
