// Helpers of the GPU tests: the device they run on (SHADOWTILE_VK_DEVICE, which ctest sets
// to lavapipe's "llvmpipe"; never whichever device comes first) and options with the
// validation layer on.
#pragma once
#include <cstdlib>
#include <string>

#include "gpu/gpu_map.hpp"

namespace st::gputest {

inline std::string device() {
  const char* e = std::getenv("SHADOWTILE_VK_DEVICE");
  return e && *e ? e : "llvmpipe";
}

inline gpu::GpuOptions options() {
  gpu::GpuOptions o;
  o.device = device();
  o.validation = true;
  o.max_queries = 1u << 16;
  o.max_pixels = 64u * 64u;
  return o;
}

}  // namespace st::gputest
