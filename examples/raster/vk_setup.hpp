// The Vulkan object set-up an engine's raster pass repeats (shader modules, descriptor
// sets, render passes, framebuffers, a graphics pipeline), written once for the raster
// example (raster.cpp) and the GPU tests' own raster pass (tests/gpu/raster_pass.hpp).
// Header-only over the Vulkan loader, no shadowtile header: what an engine already has
// in some form. Every create throws std::runtime_error naming the call that failed.
#pragma once
#include <vulkan/vulkan.h>

#include <cstdint>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

namespace vk_setup {

inline void check(VkResult r, const char* what) {
  if (r != VK_SUCCESS) throw std::runtime_error(std::string(what) + " failed: VkResult " + std::to_string(int(r)));
}

inline VkShaderModule shader_module(VkDevice d, std::span<const uint32_t> spirv) {
  VkShaderModuleCreateInfo ci{};
  ci.sType = VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO;
  ci.codeSize = spirv.size() * 4;
  ci.pCode = spirv.data();
  VkShaderModule m = VK_NULL_HANDLE;
  check(vkCreateShaderModule(d, &ci, nullptr, &m), "vkCreateShaderModule");
  return m;
}

// A shader module destroyed with its scope (a pipeline holds what it needs of it).
struct ShaderModule {
  VkDevice device;
  VkShaderModule module;
  ShaderModule(VkDevice d, std::span<const uint32_t> spirv) : device(d), module(shader_module(d, spirv)) {}
  ~ShaderModule() { vkDestroyShaderModule(device, module, nullptr); }
  ShaderModule(const ShaderModule&) = delete;
  ShaderModule& operator=(const ShaderModule&) = delete;
};

// `count` bindings numbered first, first + step, ... of one type, seen by `stages`.
inline std::vector<VkDescriptorSetLayoutBinding> bindings(uint32_t count, VkDescriptorType type,
                                                          VkShaderStageFlags stages, uint32_t first = 0,
                                                          uint32_t step = 1) {
  std::vector<VkDescriptorSetLayoutBinding> b(count);
  for (uint32_t i = 0; i < count; ++i) b[i] = {first + step * i, type, 1, stages, nullptr};
  return b;
}

inline VkDescriptorSetLayout set_layout(VkDevice d, std::span<const VkDescriptorSetLayoutBinding> b) {
  VkDescriptorSetLayoutCreateInfo ci{};
  ci.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO;
  ci.bindingCount = uint32_t(b.size());
  ci.pBindings = b.data();
  VkDescriptorSetLayout l = VK_NULL_HANDLE;
  check(vkCreateDescriptorSetLayout(d, &ci, nullptr, &l), "vkCreateDescriptorSetLayout");
  return l;
}

inline VkPipelineLayout pipeline_layout(VkDevice d, std::span<const VkDescriptorSetLayout> sets,
                                        const VkPushConstantRange& push) {
  VkPipelineLayoutCreateInfo ci{};
  ci.sType = VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO;
  ci.setLayoutCount = uint32_t(sets.size());
  ci.pSetLayouts = sets.data();
  ci.pushConstantRangeCount = push.size ? 1 : 0;
  ci.pPushConstantRanges = &push;
  VkPipelineLayout l = VK_NULL_HANDLE;
  check(vkCreatePipelineLayout(d, &ci, nullptr, &l), "vkCreatePipelineLayout");
  return l;
}

inline VkDescriptorPool descriptor_pool(VkDevice d, uint32_t max_sets, std::span<const VkDescriptorPoolSize> sizes) {
  VkDescriptorPoolCreateInfo ci{};
  ci.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO;
  ci.maxSets = max_sets;
  ci.poolSizeCount = uint32_t(sizes.size());
  ci.pPoolSizes = sizes.data();
  VkDescriptorPool p = VK_NULL_HANDLE;
  check(vkCreateDescriptorPool(d, &ci, nullptr, &p), "vkCreateDescriptorPool");
  return p;
}

inline VkDescriptorSet allocate_set(VkDevice d, VkDescriptorPool pool, VkDescriptorSetLayout layout) {
  VkDescriptorSetAllocateInfo ai{};
  ai.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO;
  ai.descriptorPool = pool;
  ai.descriptorSetCount = 1;
  ai.pSetLayouts = &layout;
  VkDescriptorSet s = VK_NULL_HANDLE;
  check(vkAllocateDescriptorSets(d, &ai, &s), "vkAllocateDescriptorSets");
  return s;
}

// Storage buffers into bindings first, first + step, ... of `set`.
inline void write_buffers(VkDevice d, VkDescriptorSet set, std::span<const VkDescriptorBufferInfo> buffers,
                          uint32_t first = 0, uint32_t step = 1) {
  std::vector<VkWriteDescriptorSet> w(buffers.size());
  for (uint32_t i = 0; i < w.size(); ++i) {
    w[i].sType = VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET;
    w[i].dstSet = set;
    w[i].dstBinding = first + step * i;
    w[i].descriptorCount = 1;
    w[i].descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
    w[i].pBufferInfo = &buffers[i];
  }
  vkUpdateDescriptorSets(d, uint32_t(w.size()), w.data(), 0, nullptr);
}

// Combined image samplers into bindings 0, 1, ... of `set`.
inline void write_images(VkDevice d, VkDescriptorSet set, std::span<const VkDescriptorImageInfo> images) {
  std::vector<VkWriteDescriptorSet> w(images.size());
  for (uint32_t i = 0; i < w.size(); ++i) {
    w[i].sType = VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET;
    w[i].dstSet = set;
    w[i].dstBinding = i;
    w[i].descriptorCount = 1;
    w[i].descriptorType = VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER;
    w[i].pImageInfo = &images[i];
  }
  vkUpdateDescriptorSets(d, uint32_t(w.size()), w.data(), 0, nullptr);
}

// An attachment of one sample, stencil unused.
inline VkAttachmentDescription attachment(VkFormat format, VkAttachmentLoadOp load, VkAttachmentStoreOp store,
                                          VkImageLayout initial, VkImageLayout final_layout) {
  VkAttachmentDescription a{};
  a.format = format;
  a.samples = VK_SAMPLE_COUNT_1_BIT;
  a.loadOp = load;
  a.storeOp = store;
  a.stencilLoadOp = VK_ATTACHMENT_LOAD_OP_DONT_CARE;
  a.stencilStoreOp = VK_ATTACHMENT_STORE_OP_DONT_CARE;
  a.initialLayout = initial;
  a.finalLayout = final_layout;
  return a;
}

// One graphics subpass: colour attachments in their optimal layout, and the depth one if any.
inline VkRenderPass render_pass(VkDevice d, std::span<const VkAttachmentDescription> attachments,
                                std::span<const VkAttachmentReference> colour, const VkAttachmentReference* depth,
                                std::span<const VkSubpassDependency> dependencies = {}) {
  VkSubpassDescription sub{};
  sub.pipelineBindPoint = VK_PIPELINE_BIND_POINT_GRAPHICS;
  sub.colorAttachmentCount = uint32_t(colour.size());
  sub.pColorAttachments = colour.data();
  sub.pDepthStencilAttachment = depth;
  VkRenderPassCreateInfo ci{};
  ci.sType = VK_STRUCTURE_TYPE_RENDER_PASS_CREATE_INFO;
  ci.attachmentCount = uint32_t(attachments.size());
  ci.pAttachments = attachments.data();
  ci.subpassCount = 1;
  ci.pSubpasses = &sub;
  ci.dependencyCount = uint32_t(dependencies.size());
  ci.pDependencies = dependencies.data();
  VkRenderPass rp = VK_NULL_HANDLE;
  check(vkCreateRenderPass(d, &ci, nullptr, &rp), "vkCreateRenderPass");
  return rp;
}

inline VkFramebuffer framebuffer(VkDevice d, VkRenderPass pass, std::span<const VkImageView> views, uint32_t width,
                                 uint32_t height) {
  VkFramebufferCreateInfo ci{};
  ci.sType = VK_STRUCTURE_TYPE_FRAMEBUFFER_CREATE_INFO;
  ci.renderPass = pass;
  ci.attachmentCount = uint32_t(views.size());
  ci.pAttachments = views.data();
  ci.width = width;
  ci.height = height;
  ci.layers = 1;
  VkFramebuffer fb = VK_NULL_HANDLE;
  check(vkCreateFramebuffer(d, &ci, nullptr, &fb), "vkCreateFramebuffer");
  return fb;
}

// A graphics pipeline of triangle lists over the whole target, no culling, one sample, no
// blending.
struct Pipeline {
  VkPipelineLayout layout = VK_NULL_HANDLE;
  VkRenderPass pass = VK_NULL_HANDLE;
  uint32_t width = 0, height = 0;
  VkShaderModule vertex = VK_NULL_HANDLE, fragment = VK_NULL_HANDLE;  // fragment may be null
  std::span<const VkVertexInputBindingDescription> vertex_bindings;
  std::span<const VkVertexInputAttributeDescription> vertex_attributes;
  const VkPipelineDepthStencilStateCreateInfo* depth = nullptr;  // null: no depth test
  uint32_t colour_attachments = 0;
  VkColorComponentFlags colour_mask = 0xF;  // written by every colour attachment
};

inline VkPipeline pipeline(VkDevice d, const Pipeline& p) {
  VkPipelineShaderStageCreateInfo stages[2] = {};
  for (int i = 0; i < 2; ++i) {
    stages[i].sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO;
    stages[i].stage = i == 0 ? VK_SHADER_STAGE_VERTEX_BIT : VK_SHADER_STAGE_FRAGMENT_BIT;
    stages[i].module = i == 0 ? p.vertex : p.fragment;
    stages[i].pName = "main";
  }
  VkPipelineVertexInputStateCreateInfo vi{};
  vi.sType = VK_STRUCTURE_TYPE_PIPELINE_VERTEX_INPUT_STATE_CREATE_INFO;
  vi.vertexBindingDescriptionCount = uint32_t(p.vertex_bindings.size());
  vi.pVertexBindingDescriptions = p.vertex_bindings.data();
  vi.vertexAttributeDescriptionCount = uint32_t(p.vertex_attributes.size());
  vi.pVertexAttributeDescriptions = p.vertex_attributes.data();
  VkPipelineInputAssemblyStateCreateInfo ia{};
  ia.sType = VK_STRUCTURE_TYPE_PIPELINE_INPUT_ASSEMBLY_STATE_CREATE_INFO;
  ia.topology = VK_PRIMITIVE_TOPOLOGY_TRIANGLE_LIST;
  const VkViewport vp{0, 0, float(p.width), float(p.height), 0, 1};
  const VkRect2D sc{{0, 0}, {p.width, p.height}};
  VkPipelineViewportStateCreateInfo vps{};
  vps.sType = VK_STRUCTURE_TYPE_PIPELINE_VIEWPORT_STATE_CREATE_INFO;
  vps.viewportCount = 1;
  vps.pViewports = &vp;
  vps.scissorCount = 1;
  vps.pScissors = &sc;
  VkPipelineRasterizationStateCreateInfo rs{};
  rs.sType = VK_STRUCTURE_TYPE_PIPELINE_RASTERIZATION_STATE_CREATE_INFO;
  rs.polygonMode = VK_POLYGON_MODE_FILL;
  rs.cullMode = VK_CULL_MODE_NONE;
  rs.lineWidth = 1;
  VkPipelineMultisampleStateCreateInfo ms{};
  ms.sType = VK_STRUCTURE_TYPE_PIPELINE_MULTISAMPLE_STATE_CREATE_INFO;
  ms.rasterizationSamples = VK_SAMPLE_COUNT_1_BIT;
  std::vector<VkPipelineColorBlendAttachmentState> blend(p.colour_attachments);
  for (auto& b : blend) b.colorWriteMask = p.colour_mask;
  VkPipelineColorBlendStateCreateInfo cb{};
  cb.sType = VK_STRUCTURE_TYPE_PIPELINE_COLOR_BLEND_STATE_CREATE_INFO;
  cb.attachmentCount = p.colour_attachments;
  cb.pAttachments = blend.data();
  VkGraphicsPipelineCreateInfo ci{};
  ci.sType = VK_STRUCTURE_TYPE_GRAPHICS_PIPELINE_CREATE_INFO;
  ci.stageCount = p.fragment ? 2 : 1;
  ci.pStages = stages;
  ci.pVertexInputState = &vi;
  ci.pInputAssemblyState = &ia;
  ci.pViewportState = &vps;
  ci.pRasterizationState = &rs;
  ci.pMultisampleState = &ms;
  ci.pDepthStencilState = p.depth;
  ci.pColorBlendState = &cb;
  ci.layout = p.layout;
  ci.renderPass = p.pass;
  VkPipeline out = VK_NULL_HANDLE;
  check(vkCreateGraphicsPipelines(d, VK_NULL_HANDLE, 1, &ci, nullptr, &out), "vkCreateGraphicsPipelines");
  return out;
}

}  // namespace vk_setup
