// Runs tests/gpu/shaders/layout_probe.comp on the named device and returns the layout
// constants the shader was compiled against, in the order the probe writes them
// (layout::kProbeWords words). Throws GpuError like GpuMap's constructor (and run_fdiv_probe also for a, b (or skew)
// of different sizes or more than 2^22 pairs). Test code: compiled into gpu_tests only,
// never into shadowtile::gpu; it drives gpu/'s internal kernels.
#pragma once
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace st::gpu {

std::vector<uint32_t> run_layout_probe(const std::string& device, bool validation, uint64_t* validation_messages);

// The same shader's other mode: the bits of st_fdiv(a[i], b[i]) (shaders/st_fdiv.glsl, the
// passes' division rounded as the CPU's) for each pair, on the device; with `skew` (empty or
// one per pair) st_fdiv_est(a[i], b[i], skew[i]): the device's estimate moved by skew[i]
// ulps before the exact steps. For the tests.
std::vector<uint32_t> run_fdiv_probe(const std::string& device, bool validation, std::span<const uint32_t> a,
                                     std::span<const uint32_t> b, std::span<const int32_t> skew,
                                     uint64_t* validation_messages);

}  // namespace st::gpu
