// <shadowtile/vk_setup.hpp>: the Vulkan object set-up every renderer repeats (buffers and
// images with their memory, command pools and buffers, fences, timestamp queries, shader
// modules, descriptor sets, render passes, framebuffers, graphics and compute pipelines),
// written once. gpu/ builds its own objects with it, through the function table it loads
// from the engine's vkGetInstanceProcAddr / vkGetDeviceProcAddr; the raster example and
// the GPU tests through the plain Vulkan loader (Loader below).
//
// Header-only, and not included by <shadowtile/gpu.hpp>: an engine that has its own
// set-up never sees it. Every function takes a Device<Vk>: the VkDevice, the allocation
// callbacks, and `vk`, any table whose members are the Vulkan entry points named without
// their "vk" prefix (vk.CreateBuffer, vk.AllocateMemory, ...), so that it runs over
// whichever loader the caller has. Only the members a function calls need to exist.
//
// Errors: a failing create calls Device::fail (gpu/ turns it into a GpuError); without
// one, it throws std::runtime_error("<call> failed: VkResult <n>"). create_buffer and
// create_image return the VkResult instead (an allocator's contract) and leave nothing
// behind on failure. The objects made are the caller's to destroy (destroy() for a
// Buffer or an Image; the matching vkDestroy* for the rest).
#pragma once
#include <vulkan/vulkan.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

namespace st::vk_setup {

template <class Vk>
struct Device {
  const Vk& vk;
  VkDevice device = VK_NULL_HANDLE;
  const VkAllocationCallbacks* callbacks = nullptr;
  void (*fail)(VkResult r, const char* call) = nullptr;  // throws; null: std::runtime_error
};

#ifndef VK_NO_PROTOTYPES
// The Vulkan loader's entry points, for a Device<Loader>{kLoader, device}.
struct Loader {
#define ST_VK_SETUP_LOADER(name) PFN_vk##name name = &vk##name;
  ST_VK_SETUP_LOADER(CreateBuffer) ST_VK_SETUP_LOADER(DestroyBuffer) ST_VK_SETUP_LOADER(GetBufferMemoryRequirements)
  ST_VK_SETUP_LOADER(CreateImage) ST_VK_SETUP_LOADER(DestroyImage) ST_VK_SETUP_LOADER(GetImageMemoryRequirements)
  ST_VK_SETUP_LOADER(CreateImageView) ST_VK_SETUP_LOADER(DestroyImageView) ST_VK_SETUP_LOADER(BindImageMemory)
  ST_VK_SETUP_LOADER(AllocateMemory) ST_VK_SETUP_LOADER(FreeMemory) ST_VK_SETUP_LOADER(BindBufferMemory)
  ST_VK_SETUP_LOADER(MapMemory) ST_VK_SETUP_LOADER(UnmapMemory)
  ST_VK_SETUP_LOADER(CreateCommandPool) ST_VK_SETUP_LOADER(AllocateCommandBuffers) ST_VK_SETUP_LOADER(CreateFence)
  ST_VK_SETUP_LOADER(CreateQueryPool)
  ST_VK_SETUP_LOADER(CreateShaderModule) ST_VK_SETUP_LOADER(DestroyShaderModule)
  ST_VK_SETUP_LOADER(CreateDescriptorSetLayout) ST_VK_SETUP_LOADER(CreatePipelineLayout)
  ST_VK_SETUP_LOADER(CreateDescriptorPool) ST_VK_SETUP_LOADER(AllocateDescriptorSets)
  ST_VK_SETUP_LOADER(UpdateDescriptorSets) ST_VK_SETUP_LOADER(CreateRenderPass) ST_VK_SETUP_LOADER(CreateFramebuffer)
  ST_VK_SETUP_LOADER(CreateGraphicsPipelines) ST_VK_SETUP_LOADER(CreateComputePipelines)
#undef ST_VK_SETUP_LOADER
};
inline const Loader kLoader{};
#endif

template <class Vk>
void check(const Device<Vk>& d, VkResult r, const char* call) {
  if (r == VK_SUCCESS) return;
  if (d.fail) d.fail(r, call);
  throw std::runtime_error(std::string(call) + " failed: VkResult " + std::to_string(int(r)));
}

// The first memory type among `bits` with every flag of `want`, else of `fallback`;
// kNoMemoryType when neither has one.
inline constexpr uint32_t kNoMemoryType = ~0u;
inline uint32_t memory_type(const VkPhysicalDeviceMemoryProperties& m, uint32_t bits, VkMemoryPropertyFlags want,
                            VkMemoryPropertyFlags fallback) {
  for (VkMemoryPropertyFlags f : {want, fallback})
    for (uint32_t i = 0; i < m.memoryTypeCount; ++i)
      if ((bits & (1u << i)) && (m.memoryTypes[i].propertyFlags & f) == f) return i;
  return kNoMemoryType;
}

// A buffer with its own vkAllocateMemory (a handful made once, not a sub-allocator).
struct Buffer {
  VkBuffer buffer = VK_NULL_HANDLE;
  VkDeviceMemory memory = VK_NULL_HANDLE;
  void* mapped = nullptr;  // the whole buffer, when made with `map`
};

template <class Vk>
void destroy(const Device<Vk>& d, Buffer& b) {
  if (b.mapped) d.vk.UnmapMemory(d.device, b.memory);
  if (b.buffer) d.vk.DestroyBuffer(d.device, b.buffer, d.callbacks);
  if (b.memory) d.vk.FreeMemory(d.device, b.memory, d.callbacks);
  b = {};
}

// `info`'s buffer in memory of flags `want` (else `fallback`), mapped when `map`. A device
// without such memory: VK_ERROR_OUT_OF_DEVICE_MEMORY.
template <class Vk>
VkResult create_buffer(const Device<Vk>& d, const VkPhysicalDeviceMemoryProperties& memory,
                       const VkBufferCreateInfo& info, VkMemoryPropertyFlags want, VkMemoryPropertyFlags fallback,
                       bool map, Buffer& out) {
  out = {};
  VkResult r = d.vk.CreateBuffer(d.device, &info, d.callbacks, &out.buffer);
  if (r != VK_SUCCESS) return r;
  VkMemoryRequirements req{};
  d.vk.GetBufferMemoryRequirements(d.device, out.buffer, &req);
  VkMemoryAllocateInfo mai{};
  mai.sType = VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO;
  mai.allocationSize = req.size;
  mai.memoryTypeIndex = memory_type(memory, req.memoryTypeBits, want, fallback);
  r = mai.memoryTypeIndex == kNoMemoryType ? VK_ERROR_OUT_OF_DEVICE_MEMORY
                                           : d.vk.AllocateMemory(d.device, &mai, d.callbacks, &out.memory);
  if (r == VK_SUCCESS) r = d.vk.BindBufferMemory(d.device, out.buffer, out.memory, 0);
  if (r == VK_SUCCESS && map) r = d.vk.MapMemory(d.device, out.memory, 0, VK_WHOLE_SIZE, 0, &out.mapped);
  if (r != VK_SUCCESS) destroy(d, out);
  return r;
}

// A 2D image of one mip level and layer, with a view.
struct Image {
  VkImage image = VK_NULL_HANDLE;
  VkDeviceMemory memory = VK_NULL_HANDLE;
  VkImageView view = VK_NULL_HANDLE;
};

template <class Vk>
void destroy(const Device<Vk>& d, Image& im) {
  if (im.view) d.vk.DestroyImageView(d.device, im.view, d.callbacks);
  if (im.image) d.vk.DestroyImage(d.device, im.image, d.callbacks);
  if (im.memory) d.vk.FreeMemory(d.device, im.memory, d.callbacks);
  im = {};
}

// Optimal tiling, one sample, device-local memory; the view of `aspect`.
template <class Vk>
VkResult create_image(const Device<Vk>& d, const VkPhysicalDeviceMemoryProperties& memory, uint32_t width,
                      uint32_t height, VkFormat format, VkImageUsageFlags usage, VkImageAspectFlags aspect, Image& out) {
  out = {};
  VkImageCreateInfo ci{};
  ci.sType = VK_STRUCTURE_TYPE_IMAGE_CREATE_INFO;
  ci.imageType = VK_IMAGE_TYPE_2D;
  ci.format = format;
  ci.extent = {width, height, 1};
  ci.mipLevels = ci.arrayLayers = 1;
  ci.samples = VK_SAMPLE_COUNT_1_BIT;
  ci.tiling = VK_IMAGE_TILING_OPTIMAL;
  ci.usage = usage;
  VkResult r = d.vk.CreateImage(d.device, &ci, d.callbacks, &out.image);
  if (r != VK_SUCCESS) return r;
  VkMemoryRequirements req{};
  d.vk.GetImageMemoryRequirements(d.device, out.image, &req);
  VkMemoryAllocateInfo mai{};
  mai.sType = VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO;
  mai.allocationSize = req.size;
  mai.memoryTypeIndex = memory_type(memory, req.memoryTypeBits, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT, 0);
  r = mai.memoryTypeIndex == kNoMemoryType ? VK_ERROR_OUT_OF_DEVICE_MEMORY
                                           : d.vk.AllocateMemory(d.device, &mai, d.callbacks, &out.memory);
  if (r == VK_SUCCESS) r = d.vk.BindImageMemory(d.device, out.image, out.memory, 0);
  if (r == VK_SUCCESS) {
    VkImageViewCreateInfo vi{};
    vi.sType = VK_STRUCTURE_TYPE_IMAGE_VIEW_CREATE_INFO;
    vi.image = out.image;
    vi.viewType = VK_IMAGE_VIEW_TYPE_2D;
    vi.format = format;
    vi.subresourceRange = {aspect, 0, 1, 0, 1};
    r = d.vk.CreateImageView(d.device, &vi, d.callbacks, &out.view);
  }
  if (r != VK_SUCCESS) destroy(d, out);
  return r;
}

// A command pool on `family`; `resettable`: its buffers can be reset one by one.
template <class Vk>
VkCommandPool command_pool(const Device<Vk>& d, uint32_t family, bool resettable) {
  VkCommandPoolCreateInfo ci{};
  ci.sType = VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO;
  ci.flags = resettable ? VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT : 0;
  ci.queueFamilyIndex = family;
  VkCommandPool p = VK_NULL_HANDLE;
  check(d, d.vk.CreateCommandPool(d.device, &ci, d.callbacks, &p), "vkCreateCommandPool");
  return p;
}

// out.size() primary command buffers from `pool` (freed with it).
template <class Vk>
void command_buffers(const Device<Vk>& d, VkCommandPool pool, std::span<VkCommandBuffer> out) {
  VkCommandBufferAllocateInfo ai{};
  ai.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO;
  ai.commandPool = pool;
  ai.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
  ai.commandBufferCount = uint32_t(out.size());
  check(d, d.vk.AllocateCommandBuffers(d.device, &ai, out.data()), "vkAllocateCommandBuffers");
}

template <class Vk>
VkFence fence(const Device<Vk>& d, bool signalled) {
  VkFenceCreateInfo ci{};
  ci.sType = VK_STRUCTURE_TYPE_FENCE_CREATE_INFO;
  ci.flags = signalled ? VK_FENCE_CREATE_SIGNALED_BIT : 0;
  VkFence f = VK_NULL_HANDLE;
  check(d, d.vk.CreateFence(d.device, &ci, d.callbacks, &f), "vkCreateFence");
  return f;
}

template <class Vk>
VkQueryPool timestamp_queries(const Device<Vk>& d, uint32_t count) {
  VkQueryPoolCreateInfo ci{};
  ci.sType = VK_STRUCTURE_TYPE_QUERY_POOL_CREATE_INFO;
  ci.queryType = VK_QUERY_TYPE_TIMESTAMP;
  ci.queryCount = count;
  VkQueryPool q = VK_NULL_HANDLE;
  check(d, d.vk.CreateQueryPool(d.device, &ci, d.callbacks, &q), "vkCreateQueryPool");
  return q;
}

template <class Vk>
VkShaderModule shader_module(const Device<Vk>& d, std::span<const uint32_t> spirv) {
  VkShaderModuleCreateInfo ci{};
  ci.sType = VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO;
  ci.codeSize = spirv.size() * 4;
  ci.pCode = spirv.data();
  VkShaderModule m = VK_NULL_HANDLE;
  check(d, d.vk.CreateShaderModule(d.device, &ci, d.callbacks, &m), "vkCreateShaderModule");
  return m;
}

// A shader module destroyed with its scope (a pipeline holds what it needs of it).
template <class Vk>
struct ShaderModule {
  Device<Vk> d;
  VkShaderModule module;
  ShaderModule(const Device<Vk>& dev, std::span<const uint32_t> spirv) : d(dev), module(shader_module(dev, spirv)) {}
  ~ShaderModule() { d.vk.DestroyShaderModule(d.device, module, d.callbacks); }
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

template <class Vk>
VkDescriptorSetLayout set_layout(const Device<Vk>& d, std::span<const VkDescriptorSetLayoutBinding> b) {
  VkDescriptorSetLayoutCreateInfo ci{};
  ci.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO;
  ci.bindingCount = uint32_t(b.size());
  ci.pBindings = b.data();
  VkDescriptorSetLayout l = VK_NULL_HANDLE;
  check(d, d.vk.CreateDescriptorSetLayout(d.device, &ci, d.callbacks, &l), "vkCreateDescriptorSetLayout");
  return l;
}

template <class Vk>
VkPipelineLayout pipeline_layout(const Device<Vk>& d, std::span<const VkDescriptorSetLayout> sets,
                                 const VkPushConstantRange& push) {
  VkPipelineLayoutCreateInfo ci{};
  ci.sType = VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO;
  ci.setLayoutCount = uint32_t(sets.size());
  ci.pSetLayouts = sets.data();
  ci.pushConstantRangeCount = push.size ? 1 : 0;
  ci.pPushConstantRanges = &push;
  VkPipelineLayout l = VK_NULL_HANDLE;
  check(d, d.vk.CreatePipelineLayout(d.device, &ci, d.callbacks, &l), "vkCreatePipelineLayout");
  return l;
}

template <class Vk>
VkDescriptorPool descriptor_pool(const Device<Vk>& d, uint32_t max_sets, std::span<const VkDescriptorPoolSize> sizes) {
  VkDescriptorPoolCreateInfo ci{};
  ci.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO;
  ci.maxSets = max_sets;
  ci.poolSizeCount = uint32_t(sizes.size());
  ci.pPoolSizes = sizes.data();
  VkDescriptorPool p = VK_NULL_HANDLE;
  check(d, d.vk.CreateDescriptorPool(d.device, &ci, d.callbacks, &p), "vkCreateDescriptorPool");
  return p;
}

template <class Vk>
VkDescriptorSet allocate_set(const Device<Vk>& d, VkDescriptorPool pool, VkDescriptorSetLayout layout) {
  VkDescriptorSetAllocateInfo ai{};
  ai.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO;
  ai.descriptorPool = pool;
  ai.descriptorSetCount = 1;
  ai.pSetLayouts = &layout;
  VkDescriptorSet s = VK_NULL_HANDLE;
  check(d, d.vk.AllocateDescriptorSets(d.device, &ai, &s), "vkAllocateDescriptorSets");
  return s;
}

namespace detail {
// Descriptors of one type into bindings first, first + step, ... of `set`, eight writes per
// vkUpdateDescriptorSets call (no allocation); `fill(write, i)` points write at item i.
template <class Vk, class Fill>
void write_descriptors(const Device<Vk>& d, VkDescriptorSet set, size_t count, VkDescriptorType type,
                       uint32_t first, uint32_t step, Fill fill) {
  VkWriteDescriptorSet w[8];
  for (size_t at = 0; at < count; at += 8) {
    const uint32_t n = uint32_t(std::min<size_t>(8, count - at));
    for (uint32_t i = 0; i < n; ++i) {
      w[i] = {};
      w[i].sType = VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET;
      w[i].dstSet = set;
      w[i].dstBinding = first + step * uint32_t(at + i);
      w[i].descriptorCount = 1;
      w[i].descriptorType = type;
      fill(w[i], at + i);
    }
    d.vk.UpdateDescriptorSets(d.device, n, w, 0, nullptr);
  }
}
}  // namespace detail

// Storage buffers into bindings first, first + step, ... of `set` (no allocation).
template <class Vk>
void write_buffers(const Device<Vk>& d, VkDescriptorSet set, std::span<const VkDescriptorBufferInfo> buffers,
                   uint32_t first = 0, uint32_t step = 1) {
  detail::write_descriptors(d, set, buffers.size(), VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, first, step,
                            [&](VkWriteDescriptorSet& w, size_t i) { w.pBufferInfo = &buffers[i]; });
}

// Uniform texel buffers (GpuDescriptors::pool_view, page_table_view) into bindings first,
// first + step, ... of `set` (no allocation).
template <class Vk>
void write_texel_buffers(const Device<Vk>& d, VkDescriptorSet set, std::span<const VkBufferView> views,
                         uint32_t first = 0, uint32_t step = 1) {
  detail::write_descriptors(d, set, views.size(), VK_DESCRIPTOR_TYPE_UNIFORM_TEXEL_BUFFER, first, step,
                            [&](VkWriteDescriptorSet& w, size_t i) { w.pTexelBufferView = &views[i]; });
}

// Combined image samplers into bindings 0, 1, ... of `set`.
template <class Vk>
void write_images(const Device<Vk>& d, VkDescriptorSet set, std::span<const VkDescriptorImageInfo> images) {
  std::vector<VkWriteDescriptorSet> w(images.size());
  for (uint32_t i = 0; i < w.size(); ++i) {
    w[i].sType = VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET;
    w[i].dstSet = set;
    w[i].dstBinding = i;
    w[i].descriptorCount = 1;
    w[i].descriptorType = VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER;
    w[i].pImageInfo = &images[i];
  }
  d.vk.UpdateDescriptorSets(d.device, uint32_t(w.size()), w.data(), 0, nullptr);
}

// A compute pipeline of `spirv`'s "main" (its shader module made and destroyed here),
// with the specialization constants `spec` if given.
template <class Vk>
VkPipeline compute_pipeline(const Device<Vk>& d, VkPipelineLayout layout, std::span<const uint32_t> spirv,
                            const VkSpecializationInfo* spec = nullptr) {
  const ShaderModule<Vk> m(d, spirv);
  VkComputePipelineCreateInfo ci{};
  ci.sType = VK_STRUCTURE_TYPE_COMPUTE_PIPELINE_CREATE_INFO;
  ci.stage.sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO;
  ci.stage.stage = VK_SHADER_STAGE_COMPUTE_BIT;
  ci.stage.module = m.module;
  ci.stage.pName = "main";
  ci.stage.pSpecializationInfo = spec;
  ci.layout = layout;
  VkPipeline p = VK_NULL_HANDLE;
  check(d, d.vk.CreateComputePipelines(d.device, VK_NULL_HANDLE, 1, &ci, d.callbacks, &p), "vkCreateComputePipelines");
  return p;
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
template <class Vk>
VkRenderPass render_pass(const Device<Vk>& d, std::span<const VkAttachmentDescription> attachments,
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
  check(d, d.vk.CreateRenderPass(d.device, &ci, d.callbacks, &rp), "vkCreateRenderPass");
  return rp;
}

template <class Vk>
VkFramebuffer framebuffer(const Device<Vk>& d, VkRenderPass pass, std::span<const VkImageView> views, uint32_t width,
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
  check(d, d.vk.CreateFramebuffer(d.device, &ci, d.callbacks, &fb), "vkCreateFramebuffer");
  return fb;
}

// A graphics pipeline of triangle lists over the whole target, no culling, one sample, no
// blending.
struct Pipeline {
  VkPipelineLayout layout = VK_NULL_HANDLE;
  VkRenderPass pass = VK_NULL_HANDLE;
  uint32_t width = 0, height = 0;
  VkShaderModule vertex = VK_NULL_HANDLE, fragment = VK_NULL_HANDLE;  // fragment may be null
  const VkSpecializationInfo* fragment_specialization = nullptr;  // the fragment shader's constants
  std::span<const VkVertexInputBindingDescription> vertex_bindings;
  std::span<const VkVertexInputAttributeDescription> vertex_attributes;
  const VkPipelineDepthStencilStateCreateInfo* depth = nullptr;  // null: no depth test
  uint32_t colour_attachments = 0;
  VkColorComponentFlags colour_mask = 0xF;  // written by every colour attachment
};

template <class Vk>
VkPipeline pipeline(const Device<Vk>& d, const Pipeline& p) {
  VkPipelineShaderStageCreateInfo stages[2] = {};
  for (int i = 0; i < 2; ++i) {
    stages[i].sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO;
    stages[i].stage = i == 0 ? VK_SHADER_STAGE_VERTEX_BIT : VK_SHADER_STAGE_FRAGMENT_BIT;
    stages[i].module = i == 0 ? p.vertex : p.fragment;
    stages[i].pName = "main";
  }
  stages[1].pSpecializationInfo = p.fragment_specialization;
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
  check(d, d.vk.CreateGraphicsPipelines(d.device, VK_NULL_HANDLE, 1, &ci, d.callbacks, &out), "vkCreateGraphicsPipelines");
  return out;
}

}  // namespace st::vk_setup
