// The engine's own raster pass of the GPU tests (tests/gpu/shaders): a full-screen
// triangle into an R32F colour attachment, its fragment shader (engine_fragment.frag)
// including shadowtile.glsl with our buffers at set 0 bindings 3, 5, 7
// (GpuMap::descriptors) and the G-buffer at set 1.
#pragma once
#include <bit>
#include <span>

#include "tests/gpu/engine_harness.hpp"

namespace st::enginetest {

const uint32_t kFullscreenVertSpv[] = {
#include "tests/gpu/fullscreen.vert.spv.inc"
};
const uint32_t kEngineFragmentSpv[] = {
#include "tests/gpu/engine_fragment.frag.spv.inc"
};
const uint32_t kEngineFragmentDeepSpv[] = {  // with partial occluders (ST_TEST_DEEP)
#include "tests/gpu/engine_fragment_deep.frag.spv.inc"
};

// The engine's own raster pass (tests/gpu/shaders): a full-screen triangle into an R32F
// colour attachment, its fragment shader including shadowtile.glsl with our buffers at
// set 0 bindings 3, 5, 7 (GpuMap::descriptors) and the G-buffer at set 1.
struct RasterPass {
  VkDevice d = VK_NULL_HANDLE;
  VkRenderPass rp = VK_NULL_HANDLE;
  VkFramebuffer fb = VK_NULL_HANDLE;
  VkSampler sampler = VK_NULL_HANDLE;
  VkDescriptorSetLayout l0 = VK_NULL_HANDLE, l1 = VK_NULL_HANDLE;
  VkPipelineLayout layout = VK_NULL_HANDLE;
  VkPipeline pipeline = VK_NULL_HANDLE;
  VkDescriptorPool pool = VK_NULL_HANDLE;
  VkDescriptorSet s0 = VK_NULL_HANDLE, s1 = VK_NULL_HANDLE;
  uint32_t width, height;

  VkShaderModule module(std::span<const uint32_t> code) const {
    VkShaderModuleCreateInfo ci{};
    ci.sType = VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO;
    ci.codeSize = code.size() * 4;
    ci.pCode = code.data();
    VkShaderModule m = VK_NULL_HANDLE;
    check(vkCreateShaderModule(d, &ci, nullptr, &m), "vkCreateShaderModule");
    return m;
  }

  // deep: the fragment shader built with partial occluders (st_shadow times st_transmittance).
  RasterPass(enginetest::TestEngine& e, const Image& target, const Image& pos, const Image& nrm,
             const gpu::GpuDescriptors& g, bool deep = false)
      : d(e.device), width(target.width), height(target.height) {
    VkAttachmentDescription att{};
    att.format = VK_FORMAT_R32_SFLOAT;
    att.samples = VK_SAMPLE_COUNT_1_BIT;
    att.loadOp = VK_ATTACHMENT_LOAD_OP_DONT_CARE;
    att.storeOp = VK_ATTACHMENT_STORE_OP_STORE;
    att.stencilLoadOp = VK_ATTACHMENT_LOAD_OP_DONT_CARE;
    att.stencilStoreOp = VK_ATTACHMENT_STORE_OP_DONT_CARE;
    att.initialLayout = VK_IMAGE_LAYOUT_UNDEFINED;
    att.finalLayout = VK_IMAGE_LAYOUT_GENERAL;
    VkAttachmentReference ref{0, VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL};
    VkSubpassDescription sub{};
    sub.pipelineBindPoint = VK_PIPELINE_BIND_POINT_GRAPHICS;
    sub.colorAttachmentCount = 1;
    sub.pColorAttachments = &ref;
    VkRenderPassCreateInfo rpi{};
    rpi.sType = VK_STRUCTURE_TYPE_RENDER_PASS_CREATE_INFO;
    rpi.attachmentCount = 1;
    rpi.pAttachments = &att;
    rpi.subpassCount = 1;
    rpi.pSubpasses = &sub;
    check(vkCreateRenderPass(d, &rpi, nullptr, &rp), "vkCreateRenderPass");
    VkFramebufferCreateInfo fbi{};
    fbi.sType = VK_STRUCTURE_TYPE_FRAMEBUFFER_CREATE_INFO;
    fbi.renderPass = rp;
    fbi.attachmentCount = 1;
    fbi.pAttachments = &target.view;
    fbi.width = width;
    fbi.height = height;
    fbi.layers = 1;
    check(vkCreateFramebuffer(d, &fbi, nullptr, &fb), "vkCreateFramebuffer");
    VkSamplerCreateInfo sci{};
    sci.sType = VK_STRUCTURE_TYPE_SAMPLER_CREATE_INFO;
    sci.magFilter = sci.minFilter = VK_FILTER_NEAREST;
    check(vkCreateSampler(d, &sci, nullptr, &sampler), "vkCreateSampler");
    VkDescriptorSetLayoutBinding b0[3] = {};
    for (uint32_t i = 0; i < 3; ++i)
      b0[i] = {3 + 2 * i, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, VK_SHADER_STAGE_FRAGMENT_BIT, nullptr};
    VkDescriptorSetLayoutBinding b1[2] = {};
    for (uint32_t i = 0; i < 2; ++i)
      b1[i] = {i, VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER, 1, VK_SHADER_STAGE_FRAGMENT_BIT, &sampler};
    VkDescriptorSetLayoutCreateInfo li{};
    li.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO;
    li.bindingCount = 3;
    li.pBindings = b0;
    check(vkCreateDescriptorSetLayout(d, &li, nullptr, &l0), "vkCreateDescriptorSetLayout");
    li.bindingCount = 2;
    li.pBindings = b1;
    check(vkCreateDescriptorSetLayout(d, &li, nullptr, &l1), "vkCreateDescriptorSetLayout");
    const VkDescriptorSetLayout sets[2] = {l0, l1};
    const VkPushConstantRange pcr{VK_SHADER_STAGE_FRAGMENT_BIT, 0, 16};
    VkPipelineLayoutCreateInfo pli{};
    pli.sType = VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO;
    pli.setLayoutCount = 2;
    pli.pSetLayouts = sets;
    pli.pushConstantRangeCount = 1;
    pli.pPushConstantRanges = &pcr;
    check(vkCreatePipelineLayout(d, &pli, nullptr, &layout), "vkCreatePipelineLayout");
    const VkDescriptorPoolSize ps[2] = {{VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 3}, {VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER, 2}};
    VkDescriptorPoolCreateInfo dpi{};
    dpi.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO;
    dpi.maxSets = 2;
    dpi.poolSizeCount = 2;
    dpi.pPoolSizes = ps;
    check(vkCreateDescriptorPool(d, &dpi, nullptr, &pool), "vkCreateDescriptorPool");
    VkDescriptorSetAllocateInfo dai{};
    dai.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO;
    dai.descriptorPool = pool;
    dai.descriptorSetCount = 2;
    dai.pSetLayouts = sets;
    VkDescriptorSet out[2];
    check(vkAllocateDescriptorSets(d, &dai, out), "vkAllocateDescriptorSets");
    s0 = out[0], s1 = out[1];
    const VkDescriptorBufferInfo bufs[3] = {g.pool, g.page_table, g.feedback};
    const VkDescriptorImageInfo imgs[2] = {{VK_NULL_HANDLE, pos.view, VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL},
                                           {VK_NULL_HANDLE, nrm.view, VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL}};
    VkWriteDescriptorSet w[5] = {};
    for (uint32_t i = 0; i < 5; ++i) {
      w[i].sType = VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET;
      w[i].descriptorCount = 1;
      if (i < 3) {
        w[i].dstSet = s0, w[i].dstBinding = 3 + 2 * i, w[i].descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
        w[i].pBufferInfo = &bufs[i];
      } else {
        w[i].dstSet = s1, w[i].dstBinding = i - 3, w[i].descriptorType = VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER;
        w[i].pImageInfo = &imgs[i - 3];
      }
    }
    vkUpdateDescriptorSets(d, 5, w, 0, nullptr);
    VkShaderModule vs = module(kFullscreenVertSpv), fs = module(deep ? std::span<const uint32_t>(kEngineFragmentDeepSpv) : std::span<const uint32_t>(kEngineFragmentSpv));
    VkPipelineShaderStageCreateInfo st[2] = {};
    for (int i = 0; i < 2; ++i) {
      st[i].sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO;
      st[i].stage = i == 0 ? VK_SHADER_STAGE_VERTEX_BIT : VK_SHADER_STAGE_FRAGMENT_BIT;
      st[i].module = i == 0 ? vs : fs;
      st[i].pName = "main";
    }
    VkPipelineVertexInputStateCreateInfo vi{};
    vi.sType = VK_STRUCTURE_TYPE_PIPELINE_VERTEX_INPUT_STATE_CREATE_INFO;
    VkPipelineInputAssemblyStateCreateInfo ia{};
    ia.sType = VK_STRUCTURE_TYPE_PIPELINE_INPUT_ASSEMBLY_STATE_CREATE_INFO;
    ia.topology = VK_PRIMITIVE_TOPOLOGY_TRIANGLE_LIST;
    const VkViewport vp{0, 0, float(width), float(height), 0, 1};
    const VkRect2D sc{{0, 0}, {width, height}};
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
    VkPipelineColorBlendAttachmentState cba{};
    cba.colorWriteMask = VK_COLOR_COMPONENT_R_BIT;
    VkPipelineColorBlendStateCreateInfo cb{};
    cb.sType = VK_STRUCTURE_TYPE_PIPELINE_COLOR_BLEND_STATE_CREATE_INFO;
    cb.attachmentCount = 1;
    cb.pAttachments = &cba;
    VkGraphicsPipelineCreateInfo gpi{};
    gpi.sType = VK_STRUCTURE_TYPE_GRAPHICS_PIPELINE_CREATE_INFO;
    gpi.stageCount = 2;
    gpi.pStages = st;
    gpi.pVertexInputState = &vi;
    gpi.pInputAssemblyState = &ia;
    gpi.pViewportState = &vps;
    gpi.pRasterizationState = &rs;
    gpi.pMultisampleState = &ms;
    gpi.pColorBlendState = &cb;
    gpi.layout = layout;
    gpi.renderPass = rp;
    const VkResult r = vkCreateGraphicsPipelines(d, VK_NULL_HANDLE, 1, &gpi, nullptr, &pipeline);
    vkDestroyShaderModule(d, vs, nullptr);
    vkDestroyShaderModule(d, fs, nullptr);
    check(r, "vkCreateGraphicsPipelines");
  }
  ~RasterPass() {
    vkDestroyPipeline(d, pipeline, nullptr);
    vkDestroyDescriptorPool(d, pool, nullptr);
    vkDestroyPipelineLayout(d, layout, nullptr);
    vkDestroyDescriptorSetLayout(d, l0, nullptr);
    vkDestroyDescriptorSetLayout(d, l1, nullptr);
    vkDestroySampler(d, sampler, nullptr);
    vkDestroyFramebuffer(d, fb, nullptr);
    vkDestroyRenderPass(d, rp, nullptr);
  }
  RasterPass(const RasterPass&) = delete;
  RasterPass& operator=(const RasterPass&) = delete;

  // channel 0: the visibility (st_visibility); 1..3: st_shadow's red, green, blue.
  void record(VkCommandBuffer cmd, uint32_t kernel, float normal_offset, float footprint, uint32_t channel = 0) const {
    VkRenderPassBeginInfo bi{};
    bi.sType = VK_STRUCTURE_TYPE_RENDER_PASS_BEGIN_INFO;
    bi.renderPass = rp;
    bi.framebuffer = fb;
    bi.renderArea = {{0, 0}, {width, height}};
    vkCmdBeginRenderPass(cmd, &bi, VK_SUBPASS_CONTENTS_INLINE);
    vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_GRAPHICS, pipeline);
    const VkDescriptorSet sets[2] = {s0, s1};
    vkCmdBindDescriptorSets(cmd, VK_PIPELINE_BIND_POINT_GRAPHICS, layout, 0, 2, sets, 0, nullptr);
    uint32_t push[4] = {kernel, std::bit_cast<uint32_t>(normal_offset), std::bit_cast<uint32_t>(footprint), channel};
    vkCmdPushConstants(cmd, layout, VK_SHADER_STAGE_FRAGMENT_BIT, 0, sizeof(push), push);
    vkCmdDraw(cmd, 3, 1, 0, 0);
    vkCmdEndRenderPass(cmd);
  }
};

}  // namespace st::enginetest
