// Runs shaders/layout_probe.comp on the named device and returns the layout constants the
// shader was compiled against, in the order the probe writes them (layout::kProbeWords
// words). For the layout test. Throws GpuError like GpuMap's constructor.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

namespace st::gpu {

std::vector<uint32_t> run_layout_probe(const std::string& device, bool validation, uint64_t* validation_messages);

}  // namespace st::gpu
