// engine_raster: a headless Vulkan rasterizer standing in for a game engine. It owns the
// instance, device, queue, command buffers, vertex buffer and render targets; it draws a
// scene with a vertex + fragment pipeline whose fragment shader includes shadowtile.glsl
// (shaders/scene.frag), and hands GpuMap only its device (engine mode): per frame
// GpuMap records the tile uploads into the engine's command buffer and reads back the
// feedback of frames the engine says completed. Shadows stream in over the frames, asked
// for by the fragment shader's feedback (nothing is prefetched). Writes one PNG a frame.
//
//   engine_raster --server HOST:PORT --map NAME --scene SPEC [--size 960x540] [--frames 8]
//                 [--frame-ms 200] [--orbit 30] [--filter] [--out engine-raster-out] [--device NAME]
//
// 3x3 PCF at the finest level, or with --filter at the two levels the pixel's footprint
// picks (MH §3.3, Map::pcf_footprint's choice; the footprint and the receiver offset as
// `shadowtile render --filter` takes them, so the two can be compared).
// 2D maps with a sun (a stack map's slice 0 would need the time: st_shadow_stack); a pack
// with a deep part (foliage, smoke, fog) shades with their transmittance per channel.
#include <vulkan/vulkan.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "shadowtile/cache_view.hpp"
#include "shadowtile/gpu.hpp"
#include "tiles/bake/png_io.hpp"
#include "tiles/bake/scene.hpp"
#include "tiles/core/light.hpp"

namespace {

using namespace st;

const uint32_t kVertSpv[] = {
#include "examples/scene.vert.spv.inc"
};
const uint32_t kFragSpv[] = {
#include "examples/scene.frag.spv.inc"
};

void check(VkResult r, const char* what) {
  if (r != VK_SUCCESS) throw std::runtime_error(std::string(what) + " failed: " + std::to_string(int(r)));
}

constexpr double kFovY = 0.9;  // the camera's vertical field of view, radians (51.57 degrees)

using Mat4 = std::array<float, 16>;  // column-major, as GLSL's mat4

Mat4 view_projection(const Vec3d& eye, const Vec3d& at, double fov_y, double aspect, double near, double far) {
  const Vec3d f = normalize(at - eye), s = normalize(cross(f, {0, 1, 0})), u = cross(s, f);
  const double t = 1.0 / std::tan(fov_y / 2);
  // Vulkan clip space: y down, depth 0..1.
  const double p00 = t / aspect, p11 = -t, p22 = far / (near - far), p32 = near * far / (near - far);
  const double v[4][3] = {{s.x, u.x, -f.x}, {s.y, u.y, -f.y}, {s.z, u.z, -f.z}, {-dot(s, eye), -dot(u, eye), dot(f, eye)}};
  Mat4 m{};
  for (int c = 0; c < 4; ++c) {  // P * V, column c
    m[c * 4 + 0] = float(p00 * v[c][0]);
    m[c * 4 + 1] = float(p11 * v[c][1]);
    m[c * 4 + 2] = float(p22 * v[c][2] + (c == 3 ? p32 : 0.0));
    m[c * 4 + 3] = float(-v[c][2]);
  }
  return m;
}

struct Args {
  std::string server, map, scene, size = "960x540", out = "engine-raster-out", device;
  uint32_t frames = 8, frame_ms = 200;
  double orbit = 30;
  bool filter = false;
};

struct Buffer {
  VkBuffer buffer = VK_NULL_HANDLE;
  VkDeviceMemory memory = VK_NULL_HANDLE;
  void* mapped = nullptr;
};

struct Engine {
  VkInstance instance = VK_NULL_HANDLE;
  VkPhysicalDevice physical = VK_NULL_HANDLE;
  VkDevice device = VK_NULL_HANDLE;
  VkQueue queue = VK_NULL_HANDLE;
  uint32_t family = ~0u;
  VkPhysicalDeviceMemoryProperties mem{};

  uint32_t type(uint32_t bits, VkMemoryPropertyFlags want) const {
    for (uint32_t i = 0; i < mem.memoryTypeCount; ++i)
      if ((bits & (1u << i)) && (mem.memoryTypes[i].propertyFlags & want) == want) return i;
    throw std::runtime_error("no memory type");
  }
  Buffer buffer(VkDeviceSize size, VkBufferUsageFlags usage) const {
    Buffer b;
    VkBufferCreateInfo bi{};
    bi.sType = VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO;
    bi.size = size;
    bi.usage = usage;
    check(vkCreateBuffer(device, &bi, nullptr, &b.buffer), "vkCreateBuffer");
    VkMemoryRequirements req{};
    vkGetBufferMemoryRequirements(device, b.buffer, &req);
    VkMemoryAllocateInfo ai{};
    ai.sType = VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO;
    ai.allocationSize = req.size;
    ai.memoryTypeIndex = type(req.memoryTypeBits, VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT);
    check(vkAllocateMemory(device, &ai, nullptr, &b.memory), "vkAllocateMemory");
    vkBindBufferMemory(device, b.buffer, b.memory, 0);
    check(vkMapMemory(device, b.memory, 0, VK_WHOLE_SIZE, 0, &b.mapped), "vkMapMemory");
    return b;
  }
  void destroy(Buffer& b) const {
    vkDestroyBuffer(device, b.buffer, nullptr);
    vkFreeMemory(device, b.memory, nullptr);
    b = {};
  }
  struct Image {
    VkImage image = VK_NULL_HANDLE;
    VkDeviceMemory memory = VK_NULL_HANDLE;
    VkImageView view = VK_NULL_HANDLE;
  };
  Image image(uint32_t w, uint32_t h, VkFormat format, VkImageUsageFlags usage, VkImageAspectFlags aspect) const {
    Image im;
    VkImageCreateInfo ci{};
    ci.sType = VK_STRUCTURE_TYPE_IMAGE_CREATE_INFO;
    ci.imageType = VK_IMAGE_TYPE_2D;
    ci.format = format;
    ci.extent = {w, h, 1};
    ci.mipLevels = ci.arrayLayers = 1;
    ci.samples = VK_SAMPLE_COUNT_1_BIT;
    ci.usage = usage;
    check(vkCreateImage(device, &ci, nullptr, &im.image), "vkCreateImage");
    VkMemoryRequirements req{};
    vkGetImageMemoryRequirements(device, im.image, &req);
    VkMemoryAllocateInfo ai{};
    ai.sType = VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO;
    ai.allocationSize = req.size;
    ai.memoryTypeIndex = type(req.memoryTypeBits, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
    check(vkAllocateMemory(device, &ai, nullptr, &im.memory), "vkAllocateMemory");
    vkBindImageMemory(device, im.image, im.memory, 0);
    VkImageViewCreateInfo vi{};
    vi.sType = VK_STRUCTURE_TYPE_IMAGE_VIEW_CREATE_INFO;
    vi.image = im.image;
    vi.viewType = VK_IMAGE_VIEW_TYPE_2D;
    vi.format = format;
    vi.subresourceRange = {aspect, 0, 1, 0, 1};
    check(vkCreateImageView(device, &vi, nullptr, &im.view), "vkCreateImageView");
    return im;
  }
  void destroy(Image& im) const {
    vkDestroyImageView(device, im.view, nullptr);
    vkDestroyImage(device, im.image, nullptr);
    vkFreeMemory(device, im.memory, nullptr);
  }
  VkShaderModule module(std::span<const uint32_t> code) const {
    VkShaderModuleCreateInfo ci{};
    ci.sType = VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO;
    ci.codeSize = code.size() * 4;
    ci.pCode = code.data();
    VkShaderModule m = VK_NULL_HANDLE;
    check(vkCreateShaderModule(device, &ci, nullptr, &m), "vkCreateShaderModule");
    return m;
  }

  explicit Engine(const std::string& name) {
    VkApplicationInfo app{};
    app.sType = VK_STRUCTURE_TYPE_APPLICATION_INFO;
    app.apiVersion = VK_API_VERSION_1_2;
    VkInstanceCreateInfo ici{};
    ici.sType = VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO;
    ici.pApplicationInfo = &app;
    check(vkCreateInstance(&ici, nullptr, &instance), "vkCreateInstance");
    uint32_t n = 0;
    vkEnumeratePhysicalDevices(instance, &n, nullptr);
    std::vector<VkPhysicalDevice> devs(n);
    vkEnumeratePhysicalDevices(instance, &n, devs.data());
    for (VkPhysicalDevice d : devs) {
      VkPhysicalDeviceProperties p{};
      vkGetPhysicalDeviceProperties(d, &p);
      if (!physical && (name.empty() || std::strstr(p.deviceName, name.c_str()))) physical = d;
    }
    if (!physical) throw std::runtime_error("no Vulkan device named like '" + name + "'");
    vkGetPhysicalDeviceMemoryProperties(physical, &mem);
    uint32_t qn = 0;
    vkGetPhysicalDeviceQueueFamilyProperties(physical, &qn, nullptr);
    std::vector<VkQueueFamilyProperties> qs(qn);
    vkGetPhysicalDeviceQueueFamilyProperties(physical, &qn, qs.data());
    for (uint32_t i = 0; i < qn && family == ~0u; ++i)
      if ((qs[i].queueFlags & VK_QUEUE_GRAPHICS_BIT) && (qs[i].queueFlags & VK_QUEUE_COMPUTE_BIT)) family = i;
    if (family == ~0u) throw std::runtime_error("no graphics + compute queue");
    const float prio = 1;
    VkDeviceQueueCreateInfo qci{};
    qci.sType = VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO;
    qci.queueFamilyIndex = family;
    qci.queueCount = 1;
    qci.pQueuePriorities = &prio;
    VkPhysicalDeviceFeatures features{};
    features.fragmentStoresAndAtomics = VK_TRUE;  // the fragment shader writes feedback
    VkDeviceCreateInfo dci{};
    dci.sType = VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO;
    dci.queueCreateInfoCount = 1;
    dci.pQueueCreateInfos = &qci;
    dci.pEnabledFeatures = &features;
    check(vkCreateDevice(physical, &dci, nullptr, &device), "vkCreateDevice");
    vkGetDeviceQueue(device, family, 0, &queue);
  }
  ~Engine() {
    vkDestroyDevice(device, nullptr);
    vkDestroyInstance(instance, nullptr);
  }
};

int run(const Args& a) {
  uint32_t width = 0, height = 0;
  if (std::sscanf(a.size.c_str(), "%ux%u", &width, &height) != 2 || width == 0 || height == 0 || width > 8192 ||
      height > 8192)
    throw std::runtime_error("--size: expected WxH, got '" + a.size + "'");
  const Scene scene = load_scene(a.scene, SceneOptions{});
  const auto colon = a.server.rfind(':');
  if (colon == std::string::npos) throw std::runtime_error("--server: expected HOST:PORT");
  client::ClientOptions co;
  co.cache_slots = 2048;
  client::Client cl({a.server.substr(0, colon), uint16_t(std::stoul(a.server.substr(colon + 1)))}, co);
  client::Map map = cl.open(a.map);
  const client::CacheView view(map);  // the map's light and levels through the public view
  const client::LightParams lp = view.light();
  const LightSpace light = LightSpace::from_array(LightKind(lp.kind), lp.params);
  if (view.stack() || !light.parallel()) throw std::runtime_error("a 2D map with a sun is needed");
  const uint32_t map_level = view.shape().finest_level;

  // Flat-shaded triangles: position and normal per corner.
  std::vector<float> verts;
  verts.reserve(scene.triangles.size() * 18);
  for (const auto& t : scene.triangles) {
    const Vec3d p0 = scene.vertices[t[0]], p1 = scene.vertices[t[1]], p2 = scene.vertices[t[2]];
    const Vec3d c = cross(p1 - p0, p2 - p0);
    const double l = length(c);
    if (!(l > 0)) continue;
    const Vec3d nrm = c / l;
    for (const Vec3d& p : {p0, p1, p2})
      for (double v : {p.x, p.y, p.z, nrm.x, nrm.y, nrm.z}) verts.push_back(float(v));
  }
  const uint32_t vertex_count = uint32_t(verts.size() / 6);

  Engine e(a.device);
  constexpr uint32_t kFrames = 2;  // frames in flight
  gpu::EngineDevice dev;
  dev.instance = e.instance;
  dev.physical_device = e.physical;
  dev.device = e.device;
  dev.queue_family = e.family;
  dev.get_instance_proc_addr = &vkGetInstanceProcAddr;
  dev.get_device_proc_addr = &vkGetDeviceProcAddr;
  gpu::GpuOptions go;
  go.frames_in_flight = kFrames;
  go.upload_budget_bytes = 8u << 20;
  gpu::GpuMap g(map, dev, go);

  Buffer vb = e.buffer(verts.size() * 4, VK_BUFFER_USAGE_VERTEX_BUFFER_BIT);
  std::memcpy(vb.mapped, verts.data(), verts.size() * 4);
  Engine::Image colour = e.image(width, height, VK_FORMAT_R8G8B8A8_UNORM,
                                 VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT | VK_IMAGE_USAGE_TRANSFER_SRC_BIT, VK_IMAGE_ASPECT_COLOR_BIT);
  Engine::Image depth = e.image(width, height, VK_FORMAT_D32_SFLOAT, VK_IMAGE_USAGE_DEPTH_STENCIL_ATTACHMENT_BIT,
                                VK_IMAGE_ASPECT_DEPTH_BIT);
  std::array<Buffer, kFrames> readback;
  for (Buffer& b : readback) b = e.buffer(size_t(width) * height * 4, VK_BUFFER_USAGE_TRANSFER_DST_BIT);

  // Render pass, our buffers in set 0 (one set per frame in flight: its feedback), pipeline.
  VkAttachmentDescription att[2] = {};
  att[0].format = VK_FORMAT_R8G8B8A8_UNORM;
  att[1].format = VK_FORMAT_D32_SFLOAT;
  for (auto& x : att) {
    x.samples = VK_SAMPLE_COUNT_1_BIT;
    x.loadOp = VK_ATTACHMENT_LOAD_OP_CLEAR;
    x.stencilLoadOp = VK_ATTACHMENT_LOAD_OP_DONT_CARE;
    x.stencilStoreOp = VK_ATTACHMENT_STORE_OP_DONT_CARE;
  }
  att[0].storeOp = VK_ATTACHMENT_STORE_OP_STORE;
  att[0].finalLayout = VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL;
  att[1].storeOp = VK_ATTACHMENT_STORE_OP_DONT_CARE;
  att[1].finalLayout = VK_IMAGE_LAYOUT_DEPTH_STENCIL_ATTACHMENT_OPTIMAL;
  const VkAttachmentReference cref{0, VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL};
  const VkAttachmentReference dref{1, VK_IMAGE_LAYOUT_DEPTH_STENCIL_ATTACHMENT_OPTIMAL};
  VkSubpassDescription sub{};
  sub.pipelineBindPoint = VK_PIPELINE_BIND_POINT_GRAPHICS;
  sub.colorAttachmentCount = 1;
  sub.pColorAttachments = &cref;
  sub.pDepthStencilAttachment = &dref;
  VkRenderPassCreateInfo rpi{};
  rpi.sType = VK_STRUCTURE_TYPE_RENDER_PASS_CREATE_INFO;
  rpi.attachmentCount = 2;
  rpi.pAttachments = att;
  rpi.subpassCount = 1;
  rpi.pSubpasses = &sub;
  VkRenderPass rp = VK_NULL_HANDLE;
  check(vkCreateRenderPass(e.device, &rpi, nullptr, &rp), "vkCreateRenderPass");
  const VkImageView views[2] = {colour.view, depth.view};
  VkFramebufferCreateInfo fbi{};
  fbi.sType = VK_STRUCTURE_TYPE_FRAMEBUFFER_CREATE_INFO;
  fbi.renderPass = rp;
  fbi.attachmentCount = 2;
  fbi.pAttachments = views;
  fbi.width = width;
  fbi.height = height;
  fbi.layers = 1;
  VkFramebuffer fb = VK_NULL_HANDLE;
  check(vkCreateFramebuffer(e.device, &fbi, nullptr, &fb), "vkCreateFramebuffer");
  VkDescriptorSetLayoutBinding b[3] = {};
  for (uint32_t i = 0; i < 3; ++i) b[i] = {i, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, VK_SHADER_STAGE_FRAGMENT_BIT, nullptr};
  VkDescriptorSetLayoutCreateInfo li{};
  li.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO;
  li.bindingCount = 3;
  li.pBindings = b;
  VkDescriptorSetLayout set_layout = VK_NULL_HANDLE;
  check(vkCreateDescriptorSetLayout(e.device, &li, nullptr, &set_layout), "vkCreateDescriptorSetLayout");
  const VkPushConstantRange pcr{VK_SHADER_STAGE_VERTEX_BIT | VK_SHADER_STAGE_FRAGMENT_BIT, 0, 96};
  VkPipelineLayoutCreateInfo pli{};
  pli.sType = VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO;
  pli.setLayoutCount = 1;
  pli.pSetLayouts = &set_layout;
  pli.pushConstantRangeCount = 1;
  pli.pPushConstantRanges = &pcr;
  VkPipelineLayout layout = VK_NULL_HANDLE;
  check(vkCreatePipelineLayout(e.device, &pli, nullptr, &layout), "vkCreatePipelineLayout");
  const VkDescriptorPoolSize ps{VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 3 * kFrames};
  VkDescriptorPoolCreateInfo dpi{};
  dpi.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO;
  dpi.maxSets = kFrames;
  dpi.poolSizeCount = 1;
  dpi.pPoolSizes = &ps;
  VkDescriptorPool dpool = VK_NULL_HANDLE;
  check(vkCreateDescriptorPool(e.device, &dpi, nullptr, &dpool), "vkCreateDescriptorPool");
  std::array<VkDescriptorSet, kFrames> sets{};
  for (uint32_t i = 0; i < kFrames; ++i) {
    VkDescriptorSetAllocateInfo dai{};
    dai.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO;
    dai.descriptorPool = dpool;
    dai.descriptorSetCount = 1;
    dai.pSetLayouts = &set_layout;
    check(vkAllocateDescriptorSets(e.device, &dai, &sets[i]), "vkAllocateDescriptorSets");
    const gpu::GpuDescriptors d = g.descriptors(i);  // ring slot i's feedback
    const VkDescriptorBufferInfo infos[3] = {d.pool, d.page_table, d.feedback};
    VkWriteDescriptorSet w[3] = {};
    for (uint32_t k = 0; k < 3; ++k) {
      w[k].sType = VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET;
      w[k].dstSet = sets[i];
      w[k].dstBinding = k;
      w[k].descriptorCount = 1;
      w[k].descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
      w[k].pBufferInfo = &infos[k];
    }
    vkUpdateDescriptorSets(e.device, 3, w, 0, nullptr);
  }
  VkShaderModule vs = e.module(kVertSpv), fs = e.module(kFragSpv);
  VkPipelineShaderStageCreateInfo st[2] = {};
  for (int i = 0; i < 2; ++i) {
    st[i].sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO;
    st[i].stage = i == 0 ? VK_SHADER_STAGE_VERTEX_BIT : VK_SHADER_STAGE_FRAGMENT_BIT;
    st[i].module = i == 0 ? vs : fs;
    st[i].pName = "main";
  }
  const VkVertexInputBindingDescription vbind{0, 24, VK_VERTEX_INPUT_RATE_VERTEX};
  const VkVertexInputAttributeDescription vattr[2] = {{0, 0, VK_FORMAT_R32G32B32_SFLOAT, 0},
                                                      {1, 0, VK_FORMAT_R32G32B32_SFLOAT, 12}};
  VkPipelineVertexInputStateCreateInfo vi{};
  vi.sType = VK_STRUCTURE_TYPE_PIPELINE_VERTEX_INPUT_STATE_CREATE_INFO;
  vi.vertexBindingDescriptionCount = 1;
  vi.pVertexBindingDescriptions = &vbind;
  vi.vertexAttributeDescriptionCount = 2;
  vi.pVertexAttributeDescriptions = vattr;
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
  VkPipelineDepthStencilStateCreateInfo ds{};
  ds.sType = VK_STRUCTURE_TYPE_PIPELINE_DEPTH_STENCIL_STATE_CREATE_INFO;
  ds.depthTestEnable = ds.depthWriteEnable = VK_TRUE;
  ds.depthCompareOp = VK_COMPARE_OP_LESS;
  VkPipelineColorBlendAttachmentState cba{};
  cba.colorWriteMask = 0xF;
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
  gpi.pDepthStencilState = &ds;
  gpi.pColorBlendState = &cb;
  gpi.layout = layout;
  gpi.renderPass = rp;
  VkPipeline pipeline = VK_NULL_HANDLE;
  check(vkCreateGraphicsPipelines(e.device, VK_NULL_HANDLE, 1, &gpi, nullptr, &pipeline), "vkCreateGraphicsPipelines");
  vkDestroyShaderModule(e.device, vs, nullptr);
  vkDestroyShaderModule(e.device, fs, nullptr);

  VkCommandPoolCreateInfo cpi{};
  cpi.sType = VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO;
  cpi.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
  cpi.queueFamilyIndex = e.family;
  VkCommandPool cpool = VK_NULL_HANDLE;
  check(vkCreateCommandPool(e.device, &cpi, nullptr, &cpool), "vkCreateCommandPool");
  std::array<VkCommandBuffer, kFrames> cmds{};
  VkCommandBufferAllocateInfo cai{};
  cai.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO;
  cai.commandPool = cpool;
  cai.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
  cai.commandBufferCount = kFrames;
  check(vkAllocateCommandBuffers(e.device, &cai, cmds.data()), "vkAllocateCommandBuffers");
  std::array<VkFence, kFrames> fences{};
  for (VkFence& f : fences) {
    VkFenceCreateInfo fci{};
    fci.sType = VK_STRUCTURE_TYPE_FENCE_CREATE_INFO;
    fci.flags = VK_FENCE_CREATE_SIGNALED_BIT;
    check(vkCreateFence(e.device, &fci, nullptr, &f), "vkCreateFence");
  }

  std::filesystem::create_directories(a.out);
  const Aabb box = scene.bounds();
  const Vec3d centre = box.center(), ext = box.extent();
  const double radius = 0.75 * std::max(ext.x, ext.z);
  const Vec3d to_sun = -light.forward();
  const float texel = float(light.extent_uv() / double(uint64_t(1) << map_level));  // one finest texel, world units
  std::array<uint64_t, kFrames> in_slot{};  // the frame each ring slot holds (0: none)
  uint64_t completed = 0;
  auto write_frame = [&](uint64_t f) {
    const auto* px = static_cast<const uint8_t*>(readback[f % kFrames].mapped);
    std::vector<Rgb8> img(size_t(width) * height);
    for (size_t i = 0; i < img.size(); ++i) img[i] = {px[4 * i], px[4 * i + 1], px[4 * i + 2]};
    char name[64];
    std::snprintf(name, sizeof(name), "/frame_%03llu.png", (unsigned long long)f);
    write_png(a.out + name, width, height, img);
  };
  std::printf("%5s %10s %10s %12s %10s %9s %9s\n", "frame", "tile B", "page B", "feedback B", "fb tiles", "requested", "holes");
  for (uint64_t f = 1; f <= a.frames; ++f) {
    const uint32_t s = uint32_t(f % kFrames);
    check(vkWaitForFences(e.device, 1, &fences[s], VK_TRUE, UINT64_MAX), "vkWaitForFences");
    check(vkResetFences(e.device, 1, &fences[s]), "vkResetFences");
    if (in_slot[s]) {
      completed = std::max(completed, in_slot[s]);
      write_frame(in_slot[s]);
    }
    for (const gpu::FrameStats& r : g.retire(completed))
      std::printf("%5llu %10llu %10llu %12llu %10u %9u %9u\n", (unsigned long long)r.frame,
                  (unsigned long long)r.tile_bytes, (unsigned long long)r.page_bytes,
                  (unsigned long long)r.feedback_bytes, r.feedback_tiles, r.requested, r.holes);
    VkCommandBuffer cmd = cmds[s];
    VkCommandBufferBeginInfo bi{};
    bi.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO;
    check(vkResetCommandBuffer(cmd, 0), "vkResetCommandBuffer");
    check(vkBeginCommandBuffer(cmd, &bi), "vkBeginCommandBuffer");
    // Partial occluders (a pack with a deep part): the fragment shader multiplies their
    // transmittance in (st_shadow); deep tiles come through the Map, not the GPU's feedback.
    if (map.has_deep()) map.deep_resident(0, 0, 0.999999, 0.999999);
    g.record_uploads(cmd, f);
    const double angle = (a.orbit * double(f - 1) + 20.0) * 3.14159265358979 / 180.0;
    const Vec3d eye = centre + Vec3d{std::cos(angle) * radius, 0.55 * radius, std::sin(angle) * radius};
    struct {
      Mat4 vp;
      float sun[4];
      float eye[4];
    } push{view_projection(eye, centre, kFovY, double(width) / height, radius * 0.02, radius * 6),
           {float(to_sun.x), float(to_sun.y), float(to_sun.z), texel},
           {float(eye.x), float(eye.y), float(eye.z), a.filter ? float(2 * std::tan(kFovY / 2) / height) : 0.0f}};
    std::printf("frame %llu: camera pos=%.3f,%.3f,%.3f,target=%.3f,%.3f,%.3f\n", (unsigned long long)f, eye.x, eye.y,
                eye.z, centre.x, centre.y, centre.z);
    VkClearValue clear[2] = {};
    clear[0].color = {{0.55f, 0.65f, 0.8f, 1.0f}};
    clear[1].depthStencil = {1.0f, 0};
    VkRenderPassBeginInfo rbi{};
    rbi.sType = VK_STRUCTURE_TYPE_RENDER_PASS_BEGIN_INFO;
    rbi.renderPass = rp;
    rbi.framebuffer = fb;
    rbi.renderArea = sc;
    rbi.clearValueCount = 2;
    rbi.pClearValues = clear;
    vkCmdBeginRenderPass(cmd, &rbi, VK_SUBPASS_CONTENTS_INLINE);
    vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_GRAPHICS, pipeline);
    vkCmdBindDescriptorSets(cmd, VK_PIPELINE_BIND_POINT_GRAPHICS, layout, 0, 1, &sets[s], 0, nullptr);
    vkCmdPushConstants(cmd, layout, VK_SHADER_STAGE_VERTEX_BIT | VK_SHADER_STAGE_FRAGMENT_BIT, 0, sizeof(push), &push);
    const VkDeviceSize zero = 0;
    vkCmdBindVertexBuffers(cmd, 0, 1, &vb.buffer, &zero);
    vkCmdDraw(cmd, vertex_count, 1, 0, 0);
    vkCmdEndRenderPass(cmd);
    VkBufferImageCopy c{};
    c.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
    c.imageExtent = {width, height, 1};
    vkCmdCopyImageToBuffer(cmd, colour.image, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, readback[s].buffer, 1, &c);
    VkMemoryBarrier mb{};
    mb.sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER;
    mb.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
    mb.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
    vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_HOST_BIT, 0, 1, &mb, 0, nullptr, 0, nullptr);
    g.record_end_of_frame(cmd, f);
    check(vkEndCommandBuffer(cmd), "vkEndCommandBuffer");
    VkSubmitInfo si{};
    si.sType = VK_STRUCTURE_TYPE_SUBMIT_INFO;
    si.commandBufferCount = 1;
    si.pCommandBuffers = &cmd;
    check(vkQueueSubmit(e.queue, 1, &si, fences[s]), "vkQueueSubmit");
    in_slot[s] = f;
    std::this_thread::sleep_for(std::chrono::milliseconds(a.frame_ms));  // the game's frame time: tiles arrive
  }
  check(vkQueueWaitIdle(e.queue), "vkQueueWaitIdle");
  for (uint64_t f : in_slot)
    if (f > completed) write_frame(f);
  for (const gpu::FrameStats& r : g.retire(a.frames))
    std::printf("%5llu %10llu %10llu %12llu %10u %9u %9u\n", (unsigned long long)r.frame,
                (unsigned long long)r.tile_bytes, (unsigned long long)r.page_bytes,
                (unsigned long long)r.feedback_bytes, r.feedback_tiles, r.requested, r.holes);
  std::printf("wrote %u frames to %s (%u triangles)\n", a.frames, a.out.c_str(), vertex_count / 3);

  for (VkFence f : fences) vkDestroyFence(e.device, f, nullptr);
  vkDestroyCommandPool(e.device, cpool, nullptr);
  vkDestroyPipeline(e.device, pipeline, nullptr);
  vkDestroyDescriptorPool(e.device, dpool, nullptr);
  vkDestroyPipelineLayout(e.device, layout, nullptr);
  vkDestroyDescriptorSetLayout(e.device, set_layout, nullptr);
  vkDestroyFramebuffer(e.device, fb, nullptr);
  vkDestroyRenderPass(e.device, rp, nullptr);
  for (Buffer& b2 : readback) e.destroy(b2);
  e.destroy(colour);
  e.destroy(depth);
  e.destroy(vb);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Args a;
  for (int i = 1; i < argc; ++i) {
    const std::string k = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) throw std::runtime_error(k + " needs a value");
      return argv[++i];
    };
    try {
      if (k == "--server") a.server = next();
      else if (k == "--map") a.map = next();
      else if (k == "--scene") a.scene = next();
      else if (k == "--size") a.size = next();
      else if (k == "--frames") a.frames = uint32_t(std::stoul(next()));
      else if (k == "--frame-ms") a.frame_ms = uint32_t(std::stoul(next()));
      else if (k == "--orbit") a.orbit = std::stod(next());
      else if (k == "--out") a.out = next();
      else if (k == "--device") a.device = next();
      else if (k == "--filter") a.filter = true;
      else throw std::runtime_error("unknown option " + k);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "engine_raster: %s\n", e.what());
      return 2;
    }
  }
  if (a.server.empty() || a.map.empty() || a.scene.empty() || a.frames == 0) {
    std::fprintf(stderr, "usage: engine_raster --server HOST:PORT --map NAME --scene SPEC [--size WxH] [--frames N] ...\n");
    return 2;
  }
  try {
    return run(a);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "engine_raster: %s\n", e.what());
    return 1;
  }
}
