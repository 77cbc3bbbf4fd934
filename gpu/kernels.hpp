// The compute pipelines of gpu/ (evaluate, shadow pass, layout probe) over one
// descriptor-set layout (shaders/st_buffers.glsl), their SPIR-V compiled by glslc at build
// time and embedded. Internal to gpu/.
#pragma once
#include <vulkan/vulkan.h>

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "gpu/layout.hpp"
#include "gpu/vk_context.hpp"

namespace st::gpu {

// r32f: bench_gpu's baseline, the finest level as a plain float image (shaders/r32f.comp).
// stack_*: the same two for stack maps (shaders/st_stack.glsl).
enum class Kernel : uint32_t {
  evaluate = 0,
  shadow_pass = 1,
  layout_probe = 2,
  r32f = 3,
  stack_evaluate = 4,
  stack_shadow_pass = 5
};
inline constexpr uint32_t kKernelCount = 6;

// The engine-mode shadow pass (shaders/engine_shadow_pass.comp), built by GpuMap itself
// with its own descriptor-set layout (images), not one of the Kernels; `light`: the
// variant that also writes the light per channel (binding 6, ST_PASS_LIGHT).
std::span<const uint32_t> engine_shadow_pass_spirv(bool light = false);

class Kernels {
 public:
  // Pipelines plus `sets` descriptor sets.
  void create(VkContext& ctx, uint32_t sets);
  // Points descriptor set `i` at the six buffers, in binding order.
  VkDescriptorSet bind(VkContext& ctx, uint32_t i, const std::array<VkBuffer, 6>& buffers);
  void record(VkCommandBuffer cmd, Kernel k, VkDescriptorSet set, const uint32_t (&pc)[layout::kPcWords]) const;
  void destroy(VkContext& ctx);

 private:
  VkDescriptorSetLayout set_layout_ = VK_NULL_HANDLE;
  VkPipelineLayout pipeline_layout_ = VK_NULL_HANDLE;
  VkDescriptorPool descriptor_pool_ = VK_NULL_HANDLE;
  std::array<VkPipeline, kKernelCount> pipelines_{};
  std::vector<VkDescriptorSet> sets_;
  const VkFunctions* vk_ = nullptr;  // the context's table (create())
};

}  // namespace st::gpu
