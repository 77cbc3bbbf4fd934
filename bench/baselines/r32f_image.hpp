// The baseline bench_gpu measures the GPU evaluators against: a map's finest level as an
// uncompressed R32F image in one storage buffer on the same device, with the same queries
// (single tap, r x r PCF) and the same shadow pass at the finest level (r32f.comp).
// Benchmark code (bench/CMakeLists.txt compiles it into bench_gpu only); it drives gpu/'s
// internal kernels.
#pragma once
#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "gpu/gpu_map.hpp"
#include "gpu/shadow_reference.hpp"

namespace st::gpu {

class R32fImage {
 public:
  // `values`: 4^level floats, row-major. Throws GpuError when the image exceeds the
  // device's maxStorageBufferRange or a Vulkan call fails.
  R32fImage(const std::string& device, uint32_t level, std::span<const float> values, uint32_t max_items);
  ~R32fImage();
  R32fImage(const R32fImage&) = delete;
  R32fImage& operator=(const R32fImage&) = delete;

  // Queries at the finest level (r clamped to 1..9; x, y of the finest level). Returns
  // the dispatch's device time in ms (0 without timestamps).
  double evaluate(std::span<const GpuQuery> queries, std::span<float> out);
  double shadow_pass(const ShadowPassInput& in, const ShadowLight& light, std::span<float> out);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace st::gpu
