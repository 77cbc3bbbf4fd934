// The engine's own raster pass of the GPU tests (tests/gpu/shaders): a full-screen
// triangle into an R32F colour attachment, its fragment shader (engine_fragment.frag)
// including shadowtile.glsl with our buffers at set 0 bindings 3, 5, 7
// (GpuMap::descriptors) and the G-buffer at set 1. The opaque shader reads the pool and
// page table as texel buffers (its GpuMap made with GpuOptions::texel_buffers), the deep one
// as storage buffers.
#pragma once
#include <array>
#include <bit>
#include <span>
#include <stdexcept>
#include <vector>

#include "shadowtile/vk_setup.hpp"
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
  // One pipeline per lookup the fragment shader makes (its specialization constant 1:
  // st_visibility, st_shadow, st_shadow_uvd_plane), each built on its first frame.
  mutable std::array<VkPipeline, 3> pipelines{};
  VkShaderModule vertex = VK_NULL_HANDLE, fragment = VK_NULL_HANDLE;
  VkDescriptorPool pool = VK_NULL_HANDLE;
  VkDescriptorSet s0 = VK_NULL_HANDLE, s1 = VK_NULL_HANDLE;
  const Image* target;
  uint32_t width, height;

  // deep: the fragment shader built with partial occluders (st_shadow times st_transmittance),
  // the pool and page table as storage buffers; else as texel buffers (g's views: the
  // GpuMap made with GpuOptions::texel_buffers).
  RasterPass(enginetest::TestEngine& e, const Image& target, const Image& pos, const Image& nrm,
             const gpu::GpuDescriptors& g, bool deep = false)
      : d(e.device), target(&target), width(target.width), height(target.height) {
    const vk_setup::Device<vk_setup::Loader> v{vk_setup::kLoader, d};
    const VkAttachmentDescription att =
        vk_setup::attachment(VK_FORMAT_R32_SFLOAT, VK_ATTACHMENT_LOAD_OP_DONT_CARE, VK_ATTACHMENT_STORE_OP_STORE,
                             VK_IMAGE_LAYOUT_UNDEFINED, VK_IMAGE_LAYOUT_GENERAL);
    const VkAttachmentReference ref{0, VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL};
    rp = vk_setup::render_pass(v, {&att, 1}, {&ref, 1}, nullptr);
    fb = vk_setup::framebuffer(v, rp, {&target.view, 1}, width, height);
    VkSamplerCreateInfo sci{};
    sci.sType = VK_STRUCTURE_TYPE_SAMPLER_CREATE_INFO;
    sci.magFilter = sci.minFilter = VK_FILTER_NEAREST;
    check(vkCreateSampler(d, &sci, nullptr, &sampler), "vkCreateSampler");
    auto b0 = vk_setup::bindings(3, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, VK_SHADER_STAGE_FRAGMENT_BIT, 3, 2);
    if (!deep) b0[0].descriptorType = b0[1].descriptorType = gpu::GpuDescriptors::texel_type;
    l0 = vk_setup::set_layout(v, b0);
    auto b1 = vk_setup::bindings(2, VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER, VK_SHADER_STAGE_FRAGMENT_BIT);
    for (auto& b : b1) b.pImmutableSamplers = &sampler;
    l1 = vk_setup::set_layout(v, b1);
    const VkDescriptorSetLayout sets[2] = {l0, l1};
    layout = vk_setup::pipeline_layout(v, sets, {VK_SHADER_STAGE_FRAGMENT_BIT, 0, 32});
    const VkDescriptorPoolSize ps[3] = {{VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 3},
                                        {gpu::GpuDescriptors::texel_type, 2},
                                        {VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER, 2}};
    pool = vk_setup::descriptor_pool(v, 2, ps);
    s0 = vk_setup::allocate_set(v, pool, l0);
    s1 = vk_setup::allocate_set(v, pool, l1);
    if (deep) {
      const VkDescriptorBufferInfo bufs[3] = {g.pool, g.page_table, g.feedback};
      vk_setup::write_buffers(v, s0, bufs, 3, 2);
    } else {
      if (!g.pool_view || !g.page_table_view) throw std::runtime_error("RasterPass: the GpuMap has no texel-buffer views");
      const VkBufferView views[2] = {g.pool_view, g.page_table_view};
      vk_setup::write_texel_buffers(v, s0, views, 3, 2);
      vk_setup::write_buffers(v, s0, {&g.feedback, 1}, 7);
    }
    const VkDescriptorImageInfo imgs[2] = {{VK_NULL_HANDLE, pos.view, VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL},
                                           {VK_NULL_HANDLE, nrm.view, VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL}};
    vk_setup::write_images(v, s1, imgs);
    vertex = vk_setup::shader_module(v, kFullscreenVertSpv);
    fragment = vk_setup::shader_module(v, deep ? std::span<const uint32_t>(kEngineFragmentDeepSpv)
                                               : std::span<const uint32_t>(kEngineFragmentSpv));
  }
  ~RasterPass() {
    for (VkPipeline p : pipelines) vkDestroyPipeline(d, p, nullptr);
    vkDestroyShaderModule(d, fragment, nullptr);
    vkDestroyShaderModule(d, vertex, nullptr);
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

  // channel 0: the visibility (st_visibility); 1..3: st_shadow's red, green, blue; 4: the
  // visibility with the receiver plane (st_receiver_slope with to_light and one finest
  // texel `texel` in world units, st_shadow_uvd_plane).
  // The pipeline of a channel's lookup (built on first use): constant 0, a 2D map (1); 1,
  // the lookup.
  VkPipeline pipeline_for(uint32_t channel) const {
    const uint32_t lookup = channel == 0 ? 0u : channel == 4 ? 2u : 1u;
    if (!pipelines[lookup]) {
      const vk_setup::Device<vk_setup::Loader> v{vk_setup::kLoader, d};
      const uint32_t constants[2] = {1u, lookup};
      const VkSpecializationMapEntry entries[2] = {{0, 0, 4}, {1, 4, 4}};
      const VkSpecializationInfo spec{2, entries, sizeof(constants), constants};
      vk_setup::Pipeline p;
      p.layout = layout, p.pass = rp, p.width = width, p.height = height;
      p.vertex = vertex, p.fragment = fragment, p.fragment_specialization = &spec;
      p.colour_attachments = 1, p.colour_mask = VK_COLOR_COMPONENT_R_BIT;
      pipelines[lookup] = vk_setup::pipeline(v, p);
    }
    return pipelines[lookup];
  }

  void record(VkCommandBuffer cmd, uint32_t kernel, float normal_offset, float footprint, uint32_t channel = 0,
              std::array<float, 3> to_light = {}, float texel = 0) const {
    VkRenderPassBeginInfo bi{};
    bi.sType = VK_STRUCTURE_TYPE_RENDER_PASS_BEGIN_INFO;
    bi.renderPass = rp;
    bi.framebuffer = fb;
    bi.renderArea = {{0, 0}, {width, height}};
    vkCmdBeginRenderPass(cmd, &bi, VK_SUBPASS_CONTENTS_INLINE);
    vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_GRAPHICS, pipeline_for(channel));
    const VkDescriptorSet sets[2] = {s0, s1};
    vkCmdBindDescriptorSets(cmd, VK_PIPELINE_BIND_POINT_GRAPHICS, layout, 0, 2, sets, 0, nullptr);
    uint32_t push[8] = {kernel,
                        std::bit_cast<uint32_t>(normal_offset),
                        std::bit_cast<uint32_t>(footprint),
                        channel,
                        std::bit_cast<uint32_t>(to_light[0]),
                        std::bit_cast<uint32_t>(to_light[1]),
                        std::bit_cast<uint32_t>(to_light[2]),
                        std::bit_cast<uint32_t>(texel)};
    vkCmdPushConstants(cmd, layout, VK_SHADER_STAGE_FRAGMENT_BIT, 0, sizeof(push), push);
    vkCmdDraw(cmd, 3, 1, 0, 0);
    vkCmdEndRenderPass(cmd);
  }

  // One engine frame through this pass, waited for (the tests read each frame at once):
  // begin (the slot's fence), retire, GpuMap's uploads, the pass, the target's copy into
  // `readback`, GpuMap's end of frame, submit, finish. Returns the uploads' stats and the
  // frames the final retire collected.
  struct Frame {
    gpu::FrameStats uploads;
    std::vector<gpu::FrameStats> retired;
  };
  Frame run_frame(TestEngine& e, gpu::GpuMap& g, uint64_t frame, const gpu::GpuBuffer& readback, uint32_t kernel,
                  float normal_offset, float footprint, uint32_t channel = 0) const {
    uint64_t completed = 0;
    VkCommandBuffer cmd = e.begin(frame, completed);
    g.retire(completed);
    Frame out;
    out.uploads = g.record_uploads(cmd, frame);
    record(cmd, kernel, normal_offset, footprint, channel);
    e.record_readback(cmd, *target, VK_IMAGE_LAYOUT_GENERAL, VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT, readback,
                      VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT);
    g.record_end_of_frame(cmd, frame);
    e.submit(frame);
    const std::span<const gpu::FrameStats> r = g.retire(e.finish());
    out.retired.assign(r.begin(), r.end());
    return out;
  }
};

}  // namespace st::enginetest
