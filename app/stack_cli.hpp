// The stack-pack side of build / verify / export / inspect (tiles/PACK.md "Stack packs"):
// each command dispatches here when its `--light` names a light set or its pack has the
// `stack` feature.
#pragma once
#include <cstdint>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

namespace st {
class PackReader;
}

namespace st::cli {

struct StackBuildArgs {
  std::string scene, light, resolution, out, up;
  std::optional<uint32_t> skip_level;
  uint32_t tile_bytes = 64 * 1024;
  int compression = 6;
  bool quiet = false;
  std::string cells = "smaller";  // --stack-cells: octree | slices | smaller
  bool split_cells = true;        // off: --no-split-cells
  bool planes = true;             // per-slice cells' slices may be plane tiles (off: --planes off)
};
void run_stack_build(const StackBuildArgs& a);

// verify: the pack's structure (PackReader::verify), then every texel of every slice
// re-traced against the lossless invariant. Exits kExitMismatch on a failure.
void verify_stack_pack(const std::string& pack, const std::string& scene, const std::string& up,
                       uint64_t max_mismatches);

// export --slice W [--level L]: one slice of a stack as an interval EXR + PNG preview.
void export_stack_slice(const std::string& pack, uint32_t slice, std::optional<uint32_t> level,
                        const std::string& out);

// inspect: the stack's fields, added to the JSON and printed.
void inspect_stack(const PackReader& r, nlohmann::json& j, bool print);

}  // namespace st::cli
