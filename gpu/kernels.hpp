// The compute pipelines of gpu/ (evaluate, shadow pass, and both for stacks) over one
// descriptor-set layout (shaders/st_buffers.glsl), their SPIR-V compiled by glslc at build
// time and embedded. Internal to gpu/. A test's probe or a benchmark's baseline brings its
// own SPIR-V over the same layout (Kernels::create's `extra`): the library ships only the
// kernels GpuMap runs.
#pragma once
#include <vulkan/vulkan.h>

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "gpu/layout.hpp"
#include "gpu/vk_context.hpp"

namespace st::gpu {

// stack_*: the same two for stack maps (shaders/st_stack.glsl).
enum class Kernel : uint32_t {
  evaluate = 0,
  shadow_pass = 1,
  stack_evaluate = 2,
  stack_shadow_pass = 3
};
inline constexpr uint32_t kKernelCount = 4;
// The i-th of the `extra` kernels given to Kernels::create.
constexpr Kernel extra_kernel(uint32_t i) { return Kernel(kKernelCount + i); }

// The engine-mode shadow pass (shaders/engine_shadow_pass.comp), built by GpuMap itself
// with its own descriptor-set layout (images), not one of the Kernels; `light`: the
// variant that also writes the light per channel (binding 6, ST_PASS_LIGHT).
std::span<const uint32_t> engine_shadow_pass_spirv(bool light = false);

class Kernels {
 public:
  // Pipelines plus `sets` descriptor sets; `extra`: SPIR-V of further compute kernels over
  // the same set layout and push constants, recorded as extra_kernel(i). The pipelines of
  // `now` and the extra ones are built here; any other kernel's on its first record (a
  // pipeline compile costs seconds to minutes from a cold shader cache on a software device,
  // so a 2D map never builds the stack kernels, nor a stack map the 2D ones).
  void create(VkContext& ctx, uint32_t sets, std::span<const Kernel> now,
              std::span<const std::span<const uint32_t>> extra = {});
  // Points descriptor set `i` at the six buffers, in binding order.
  VkDescriptorSet bind(VkContext& ctx, uint32_t i, const std::array<VkBuffer, 6>& buffers);
  void record(VkCommandBuffer cmd, Kernel k, VkDescriptorSet set, const uint32_t (&pc)[layout::kPcWords]) const;
  void destroy(VkContext& ctx);

 private:
  VkDescriptorSetLayout set_layout_ = VK_NULL_HANDLE;
  VkPipelineLayout pipeline_layout_ = VK_NULL_HANDLE;
  VkDescriptorPool descriptor_pool_ = VK_NULL_HANDLE;
  mutable std::vector<VkPipeline> pipelines_;  // VK_NULL_HANDLE: not built yet
  std::vector<std::span<const uint32_t>> code_;
  VkContext* ctx_ = nullptr;
  std::vector<VkDescriptorSet> sets_;
  const VkFunctions* vk_ = nullptr;  // the context's table (create())
};

}  // namespace st::gpu
