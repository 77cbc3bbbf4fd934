#include "app/pack_cli_util.hpp"

#include <cstdio>

#include "common/error.hpp"

namespace st::cli {

std::string feature_names(uint32_t flags) {
  std::string s;
  auto add = [&](uint32_t bit, const char* name) {
    if (!(flags & bit)) return;
    if (!s.empty()) s.push_back(',');
    s.append(name);
  };
  add(kFeatureExitDepths, "exit-depths");
  add(kFeatureStack, "stack");
  add(kFeatureHasTiles, "tiles");
  add(kFeatureIndexTiles, "index-tiles");
  add(kFeatureDeepShadow, "deep-shadow");
  add(kFeatureStaticIntervals, "static-intervals");
  add(kFeatureDagmhDictionary, "dagmh-dictionary");
  add(kFeatureCompressedGrid, "compressed-grid");
  add(kFeaturePayloadsOnly, "payloads-only");
  add(kFeatureMixedTiles, "mixed-tiles");
  add(kFeatureStackSliceTiles, "stack-slice-tiles");
  add(kFeatureStackGroupedTiles, "stack-grouped-tiles");
  add(kFeaturePlaneTiles, "plane-tiles");
  add(kFeaturePackedPlaneTiles, "packed-plane-tiles");
  add(kFeaturePredictedPlaneLabels, "predicted-plane-labels");
  add(kFeatureStackSplitCells, "stack-split-cells");
  add(kFeatureWidePlaneBlocks, "wide-plane-blocks");
  return s.empty() ? "none" : s;
}

Rect parse_rect(const std::string& option, const std::string& text) {
  unsigned long long v[4];
  char tail = 0;
  if (std::sscanf(text.c_str(), "%llu,%llu,%llu,%llu%c", &v[0], &v[1], &v[2], &v[3], &tail) != 4 ||
      text.find('-') != std::string::npos)
    throw Error(option + ": expected X,Y,W,H (non-negative integers), got '" + text + "'");
  return {v[0], v[1], v[2], v[3]};
}

Rect built_region(const PackReader& reader) {
  for (auto& [k, v] : reader.params())
    if (k == "region") return parse_rect("pack parameter 'region'", v);
  uint64_t side = uint64_t(1) << reader.map_level();
  return {0, 0, side, side};
}

}  // namespace st::cli
