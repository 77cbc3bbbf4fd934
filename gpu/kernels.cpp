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

void Kernels::create(VkContext& ctx, uint32_t sets, std::span<const std::span<const uint32_t>> extra) {
  vk_ = &ctx.vk;
  VkDevice d = ctx.device();
  VkDescriptorSetLayoutBinding b[6] = {};
  for (uint32_t i = 0; i < 6; ++i) {
    b[i].binding = i;
    b[i].descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
    b[i].descriptorCount = 1;
    b[i].stageFlags = VK_SHADER_STAGE_COMPUTE_BIT;
  }
  VkDescriptorSetLayoutCreateInfo sli{};
  sli.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO;
  sli.bindingCount = 6;
  sli.pBindings = b;
  vk_check(vk_->CreateDescriptorSetLayout(d, &sli, nullptr, &set_layout_), "vkCreateDescriptorSetLayout");
  VkPushConstantRange pcr{VK_SHADER_STAGE_COMPUTE_BIT, 0, layout::kPcWords * 4};
  VkPipelineLayoutCreateInfo pli{};
  pli.sType = VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO;
  pli.setLayoutCount = 1;
  pli.pSetLayouts = &set_layout_;
  pli.pushConstantRangeCount = 1;
  pli.pPushConstantRanges = &pcr;
  vk_check(vk_->CreatePipelineLayout(d, &pli, nullptr, &pipeline_layout_), "vkCreatePipelineLayout");
  VkDescriptorPoolSize ps{VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 6 * sets};
  VkDescriptorPoolCreateInfo dpi{};
  dpi.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO;
  dpi.maxSets = sets;
  dpi.poolSizeCount = 1;
  dpi.pPoolSizes = &ps;
  vk_check(vk_->CreateDescriptorPool(d, &dpi, nullptr, &descriptor_pool_), "vkCreateDescriptorPool");
  sets_.assign(sets, VK_NULL_HANDLE);
  std::vector<VkDescriptorSetLayout> layouts(sets, set_layout_);
  VkDescriptorSetAllocateInfo dai{};
  dai.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO;
  dai.descriptorPool = descriptor_pool_;
  dai.descriptorSetCount = sets;
  dai.pSetLayouts = layouts.data();
  vk_check(vk_->AllocateDescriptorSets(d, &dai, sets_.data()), "vkAllocateDescriptorSets");

  std::vector<std::span<const uint32_t>> code = {kEvaluateSpv, kShadowPassSpv, kStackEvaluateSpv, kStackShadowPassSpv};
  code.insert(code.end(), extra.begin(), extra.end());
  pipelines_.assign(code.size(), VK_NULL_HANDLE);
  for (size_t i = 0; i < code.size(); ++i) {
    VkShaderModule m = ctx.make_shader(code[i]);
    VkComputePipelineCreateInfo cpi{};
    cpi.sType = VK_STRUCTURE_TYPE_COMPUTE_PIPELINE_CREATE_INFO;
    cpi.stage.sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO;
    cpi.stage.stage = VK_SHADER_STAGE_COMPUTE_BIT;
    cpi.stage.module = m;
    cpi.stage.pName = "main";
    cpi.layout = pipeline_layout_;
    const VkResult r = vk_->CreateComputePipelines(d, VK_NULL_HANDLE, 1, &cpi, nullptr, &pipelines_[i]);
    vk_->DestroyShaderModule(d, m, nullptr);
    vk_check(r, "vkCreateComputePipelines");
  }
}

VkDescriptorSet Kernels::bind(VkContext& ctx, uint32_t i, const std::array<VkBuffer, 6>& buffers) {
  VkDescriptorBufferInfo info[6];
  VkWriteDescriptorSet w[6] = {};
  for (uint32_t b = 0; b < 6; ++b) {
    info[b] = {buffers[b], 0, VK_WHOLE_SIZE};
    w[b].sType = VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET;
    w[b].dstSet = sets_[i];
    w[b].dstBinding = b;
    w[b].descriptorCount = 1;
    w[b].descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
    w[b].pBufferInfo = &info[b];
  }
  vk_->UpdateDescriptorSets(ctx.device(), 6, w, 0, nullptr);
  return sets_[i];
}

void Kernels::record(VkCommandBuffer cmd, Kernel k, VkDescriptorSet set, const uint32_t (&pc)[layout::kPcWords]) const {
  vk_->CmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, pipelines_[uint32_t(k)]);
  vk_->CmdBindDescriptorSets(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline_layout_, 0, 1, &set, 0, nullptr);
  vk_->CmdPushConstants(cmd, pipeline_layout_, VK_SHADER_STAGE_COMPUTE_BIT, 0, sizeof(pc), pc);
}

void Kernels::destroy(VkContext& ctx) {
  if (!vk_) return;
  VkDevice d = ctx.device();
  for (VkPipeline& p : pipelines_)
    if (p) vk_->DestroyPipeline(d, p, nullptr), p = VK_NULL_HANDLE;
  pipelines_.clear();
  if (descriptor_pool_) vk_->DestroyDescriptorPool(d, descriptor_pool_, nullptr);
  if (pipeline_layout_) vk_->DestroyPipelineLayout(d, pipeline_layout_, nullptr);
  if (set_layout_) vk_->DestroyDescriptorSetLayout(d, set_layout_, nullptr);
  descriptor_pool_ = VK_NULL_HANDLE;
  pipeline_layout_ = VK_NULL_HANDLE;
  set_layout_ = VK_NULL_HANDLE;
  sets_.clear();
}

}  // namespace st::gpu
