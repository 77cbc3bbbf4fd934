#include "gpu/kernels.hpp"

namespace st::gpu {
namespace {

const uint32_t kEvaluateSpv[] = {
#include "gpu/shaders/evaluate.spv.inc"
};
const uint32_t kShadowPassSpv[] = {
#include "gpu/shaders/shadow_pass.spv.inc"
};
const uint32_t kStackEvaluateSpv[] = {
#include "gpu/shaders/stack_evaluate.spv.inc"
};
const uint32_t kStackShadowPassSpv[] = {
#include "gpu/shaders/stack_shadow_pass.spv.inc"
};

const uint32_t kEngineShadowPassSpv[] = {
#include "gpu/shaders/engine_shadow_pass.spv.inc"
};

const uint32_t kEngineShadowLightPassSpv[] = {
#include "gpu/shaders/engine_shadow_light_pass.spv.inc"
};

}  // namespace

std::span<const uint32_t> engine_shadow_pass_spirv(bool light) {
  if (light) return kEngineShadowLightPassSpv;
  return kEngineShadowPassSpv;
}

void Kernels::create(VkContext& ctx, uint32_t sets, std::span<const Kernel> now,
                     std::span<const std::span<const uint32_t>> extra) {
  vk_ = &ctx.vk;
  ctx_ = &ctx;
  const auto d = ctx.setup();
  set_layout_ = vk_setup::set_layout(d, vk_setup::bindings(6, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, VK_SHADER_STAGE_COMPUTE_BIT));
  pipeline_layout_ = vk_setup::pipeline_layout(d, {&set_layout_, 1}, {VK_SHADER_STAGE_COMPUTE_BIT, 0, layout::kPcWords * 4});
  const VkDescriptorPoolSize ps{VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 6 * sets};
  descriptor_pool_ = vk_setup::descriptor_pool(d, sets, {&ps, 1});
  sets_.assign(sets, VK_NULL_HANDLE);
  for (VkDescriptorSet& s : sets_) s = vk_setup::allocate_set(d, descriptor_pool_, set_layout_);

  code_ = {kEvaluateSpv, kShadowPassSpv, kStackEvaluateSpv, kStackShadowPassSpv};
  code_.insert(code_.end(), extra.begin(), extra.end());
  pipelines_.assign(code_.size(), VK_NULL_HANDLE);
  for (const Kernel k : now) pipelines_[uint32_t(k)] = vk_setup::compute_pipeline(d, pipeline_layout_, code_[uint32_t(k)]);
  for (size_t i = kKernelCount; i < code_.size(); ++i)
    pipelines_[i] = vk_setup::compute_pipeline(d, pipeline_layout_, code_[i]);
}

VkDescriptorSet Kernels::bind(VkContext& ctx, uint32_t i, const std::array<VkBuffer, 6>& buffers) {
  VkDescriptorBufferInfo info[6];
  for (uint32_t b = 0; b < 6; ++b) info[b] = {buffers[b], 0, VK_WHOLE_SIZE};
  vk_setup::write_buffers(ctx.setup(), sets_[i], info);
  return sets_[i];
}

void Kernels::record(VkCommandBuffer cmd, Kernel k, VkDescriptorSet set, const uint32_t (&pc)[layout::kPcWords]) const {
  VkPipeline& p = pipelines_[uint32_t(k)];
  if (!p) p = vk_setup::compute_pipeline(ctx_->setup(), pipeline_layout_, code_[uint32_t(k)]);
  vk_->CmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, p);
  vk_->CmdBindDescriptorSets(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline_layout_, 0, 1, &set, 0, nullptr);
  vk_->CmdPushConstants(cmd, pipeline_layout_, VK_SHADER_STAGE_COMPUTE_BIT, 0, sizeof(pc), pc);
}

void Kernels::destroy(VkContext& ctx) {
  if (!vk_) return;
  VkDevice d = ctx.device();
  const VkAllocationCallbacks* cb = ctx.callbacks();  // as created (vk_setup, ctx.setup())
  for (VkPipeline& p : pipelines_)
    if (p) vk_->DestroyPipeline(d, p, cb), p = VK_NULL_HANDLE;
  pipelines_.clear();
  code_.clear();
  if (descriptor_pool_) vk_->DestroyDescriptorPool(d, descriptor_pool_, cb);
  if (pipeline_layout_) vk_->DestroyPipelineLayout(d, pipeline_layout_, cb);
  if (set_layout_) vk_->DestroyDescriptorSetLayout(d, set_layout_, cb);
  descriptor_pool_ = VK_NULL_HANDLE;
  pipeline_layout_ = VK_NULL_HANDLE;
  set_layout_ = VK_NULL_HANDLE;
  sets_.clear();
}

}  // namespace st::gpu
