// The headless rasterizer of raster.hpp: the engine's side of engine mode, written the way
// a renderer would (its own Vulkan objects; GpuMap only records into its command buffers).
#include "examples/raster/raster.hpp"

#include <vulkan/vulkan.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <stdexcept>

#include "examples/raster/engine_device.hpp"
#include "shadowtile/vk_setup.hpp"  // the Vulkan set-up, over the plain loader
#include "tiles/core/camera.hpp"  // header-only: the pinhole camera `shadowtile render` uses

namespace st::raster {
namespace {

const uint32_t kVertSpv[] = {
#include "examples/scene.vert.spv.inc"
};
const uint32_t kFragSpv[] = {
#include "examples/scene.frag.spv.inc"
};
const uint32_t kFragTwinSpv[] = {
#include "examples/scene_twin.frag.spv.inc"
};

void check(VkResult r, const char* what) {
  if (r != VK_SUCCESS) throw std::runtime_error(std::string(what) + " failed: VkResult " + std::to_string(int(r)));
}

using Clock = std::chrono::steady_clock;
double us_since(Clock::time_point t0) { return std::chrono::duration<double, std::micro>(Clock::now() - t0).count(); }

constexpr uint32_t kStamps = 5;  // begin, uploads done, depth pre-pass done, shading done, copies done

using Buffer = vk_setup::Buffer;
using Image = vk_setup::Image;

// The engine's device (engine_device.hpp: instance, physical device, one graphics + compute
// queue) and the rasterizer's memory on it.
struct Device : VulkanDevice {
  Device(const std::string& want, bool validation) : VulkanDevice(options(want, validation)) {}
  static EngineDeviceOptions options(const std::string& want, bool validation) {
    EngineDeviceOptions o;
    o.device = want, o.validation = validation;
    return o;
  }

  vk_setup::Device<vk_setup::Loader> setup() const { return {vk_setup::kLoader, device}; }
  // Host-visible, coherent and mapped.
  Buffer buffer(VkDeviceSize size, VkBufferUsageFlags usage) const {
    VkBufferCreateInfo bi{};
    bi.sType = VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO;
    bi.size = std::max<VkDeviceSize>(size, 4);
    bi.usage = usage;
    const VkMemoryPropertyFlags hv = VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT;
    Buffer b;
    check(vk_setup::create_buffer(setup(), mem, bi, hv, hv, true, b), "creating a buffer");
    return b;
  }
  void destroy(Buffer& b) const { vk_setup::destroy(setup(), b); }
  Image image(uint32_t w, uint32_t h, VkFormat format, VkImageUsageFlags usage, VkImageAspectFlags aspect) const {
    Image im;
    check(vk_setup::create_image(setup(), mem, w, h, format, usage, aspect, im), "creating an image");
    return im;
  }
  void destroy(Image& im) const { vk_setup::destroy(setup(), im); }
};

// The shaders' push constants (examples/shaders/scene.vert, scene.frag): 128 bytes.
struct Push {
  std::array<float, 16> view_projection;
  float light[4];   // xyz: toward a sun, or a point light's position; w: 1 for a point
  float eye[4];     // xyz: the camera; w: the pixel's angle (radians), 0: the finest level
  uint32_t mode[4]; // lookup, kernel, slice a | slice b << 16, soft
  float misc[4];    // blend f, one finest texel (world), offset in texels, filtered offset in texels
};
static_assert(sizeof(Push) == 128);

}  // namespace

std::array<float, 16> vulkan_view_projection(const FrameInput& in, double aspect, double near_plane, double far_plane) {
  Camera c;
  c.pos = {in.eye[0], in.eye[1], in.eye[2]};
  c.target = {in.target[0], in.target[1], in.target[2]};
  c.fov_deg = in.fov_deg;
  c.aspect = aspect;
  const std::array<double, 16> gl = view_projection(c, near_plane, far_plane);  // OpenGL: y up, depth -1..1
  std::array<float, 16> m{};
  for (int col = 0; col < 4; ++col) {
    const double* g = &gl[size_t(col) * 4];
    m[size_t(col) * 4 + 0] = float(g[0]);
    m[size_t(col) * 4 + 1] = float(-g[1]);                 // Vulkan: y down
    m[size_t(col) * 4 + 2] = float(0.5 * g[2] + 0.5 * g[3]);  // depth 0..1
    m[size_t(col) * 4 + 3] = float(g[3]);
  }
  return m;
}

struct Rasterizer::Impl {
  RasterOptions o;
  client::Map map;
  Device dev;
  std::unique_ptr<gpu::GpuMap> g;
  uint32_t vertex_count = 0;
  std::array<double, 3> lo{}, hi{};  // the scene's box (near and far planes)
  Buffer vb;
  Image colour, depth, receivers, visibility, r32f;
  VkSampler sampler = VK_NULL_HANDLE;
  VkRenderPass rp_depth = VK_NULL_HANDLE, rp_shade = VK_NULL_HANDLE;
  VkFramebuffer fb_depth = VK_NULL_HANDLE, fb_shade = VK_NULL_HANDLE;
  VkDescriptorSetLayout set_layout = VK_NULL_HANDLE, map_layout = VK_NULL_HANDLE;
  VkPipelineLayout layout = VK_NULL_HANDLE;
  VkDescriptorPool dpool = VK_NULL_HANDLE;
  std::vector<VkDescriptorSet> sets;
  VkDescriptorSet map_set = VK_NULL_HANDLE;
  VkPipeline depth_pipeline = VK_NULL_HANDLE, shade_pipeline = VK_NULL_HANDLE;
  VkCommandPool cpool = VK_NULL_HANDLE;
  std::vector<VkCommandBuffer> cmds;
  std::vector<VkFence> fences;
  VkQueryPool queries = VK_NULL_HANDLE;
  struct Slot {
    uint64_t frame = 0;  // the frame it runs (0: none)
    Buffer rgba, rec, vis;
    double host_us = 0, retire_us = 0, uploads_us = 0;
  };
  std::vector<Slot> slots;
  uint64_t frame = 0, completed = 0, waits = 0;
  double retire_us = 0;
  std::vector<FrameResult> done;
  std::vector<std::vector<uint8_t>> done_rgba;
  std::vector<std::vector<float>> done_rec, done_vis, done_slopes;

  Impl(client::Map m, std::span<const float> tri, const RasterOptions& opt) : o(opt), map(std::move(m)), dev(opt.device, opt.validation) {
    if (o.width == 0 || o.height == 0 || o.width > 8192 || o.height > 8192)
      throw std::runtime_error("raster: size " + std::to_string(o.width) + "x" + std::to_string(o.height) + " (1..8192 each)");
    if (o.frames_in_flight < 1 || o.frames_in_flight > 4) throw std::runtime_error("raster: frames in flight 1..4");
    if (tri.empty() || tri.size() % 18) throw std::runtime_error("raster: no triangles (6 floats a corner, 3 corners each)");
    vertex_count = uint32_t(tri.size() / 6);
    lo = {tri[0], tri[1], tri[2]}, hi = lo;
    for (size_t i = 0; i < tri.size(); i += 6)
      for (int k = 0; k < 3; ++k) lo[k] = std::min<double>(lo[k], tri[i + k]), hi[k] = std::max<double>(hi[k], tri[i + k]);

    const gpu::EngineDevice ed = dev.engine_device();
    gpu::GpuOptions go;
    go.frames_in_flight = o.frames_in_flight;
    go.upload_budget_bytes = o.upload_budget_bytes;
    go.feedback_capacity = o.feedback_capacity;
    g = std::make_unique<gpu::GpuMap>(map, ed, go);

    vb = dev.buffer(tri.size() * 4, VK_BUFFER_USAGE_VERTEX_BUFFER_BIT);
    std::memcpy(vb.mapped, tri.data(), tri.size() * 4);
    colour = dev.image(o.width, o.height, VK_FORMAT_R8G8B8A8_UNORM,
                       VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT | VK_IMAGE_USAGE_TRANSFER_SRC_BIT, VK_IMAGE_ASPECT_COLOR_BIT);
    depth = dev.image(o.width, o.height, VK_FORMAT_D32_SFLOAT, VK_IMAGE_USAGE_DEPTH_STENCIL_ATTACHMENT_BIT,
                      VK_IMAGE_ASPECT_DEPTH_BIT);
    if (o.twin) {
      receivers = dev.image(o.width, o.height, VK_FORMAT_R32G32B32A32_SFLOAT,
                            VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT | VK_IMAGE_USAGE_TRANSFER_SRC_BIT, VK_IMAGE_ASPECT_COLOR_BIT);
      visibility = dev.image(o.width, o.height, VK_FORMAT_R32G32B32A32_SFLOAT,
                             VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT | VK_IMAGE_USAGE_TRANSFER_SRC_BIT, VK_IMAGE_ASPECT_COLOR_BIT);
    }
    const size_t pixels = size_t(o.width) * o.height;
    slots.resize(o.frames_in_flight);
    for (Slot& s : slots) {
      if (o.readback) s.rgba = dev.buffer(pixels * 4, VK_BUFFER_USAGE_TRANSFER_DST_BIT);
      if (o.twin) {
        s.rec = dev.buffer(pixels * 16, VK_BUFFER_USAGE_TRANSFER_DST_BIT);
        s.vis = dev.buffer(pixels * 16, VK_BUFFER_USAGE_TRANSFER_DST_BIT);  // visibility, slopes, 0
      }
    }
    make_commands();
    make_r32f();
    make_passes();
    make_pipelines();
  }

  ~Impl() {
    if (dev.device) vkDeviceWaitIdle(dev.device);
    g.reset();  // before the device goes
    VkDevice d = dev.device;
    for (VkFence f : fences) vkDestroyFence(d, f, nullptr);
    if (queries) vkDestroyQueryPool(d, queries, nullptr);
    if (cpool) vkDestroyCommandPool(d, cpool, nullptr);
    if (depth_pipeline) vkDestroyPipeline(d, depth_pipeline, nullptr);
    if (shade_pipeline) vkDestroyPipeline(d, shade_pipeline, nullptr);
    if (dpool) vkDestroyDescriptorPool(d, dpool, nullptr);
    if (layout) vkDestroyPipelineLayout(d, layout, nullptr);
    if (set_layout) vkDestroyDescriptorSetLayout(d, set_layout, nullptr);
    if (map_layout) vkDestroyDescriptorSetLayout(d, map_layout, nullptr);
    if (fb_depth) vkDestroyFramebuffer(d, fb_depth, nullptr);
    if (fb_shade) vkDestroyFramebuffer(d, fb_shade, nullptr);
    if (rp_depth) vkDestroyRenderPass(d, rp_depth, nullptr);
    if (rp_shade) vkDestroyRenderPass(d, rp_shade, nullptr);
    if (sampler) vkDestroySampler(d, sampler, nullptr);
    for (Slot& s : slots) dev.destroy(s.rgba), dev.destroy(s.rec), dev.destroy(s.vis);
    for (Image* im : {&colour, &depth, &receivers, &visibility, &r32f}) dev.destroy(*im);
    dev.destroy(vb);
  }

  void make_commands() {
    const auto d = dev.setup();
    cpool = vk_setup::command_pool(d, dev.family, true);
    cmds.resize(o.frames_in_flight);
    vk_setup::command_buffers(d, cpool, cmds);
    fences.resize(o.frames_in_flight);
    for (VkFence& f : fences) f = vk_setup::fence(d, true);
    if (dev.timestamp_bits) queries = vk_setup::timestamp_queries(d, kStamps * o.frames_in_flight);
  }

  // The plain depth map of Lookup::r32f: uploaded once, at set-up (never per frame).
  void make_r32f() {
    const uint32_t side = o.r32f.empty() ? 1u : 1u << o.r32f_level;
    if (!o.r32f.empty() && (o.r32f_level > 14 || o.r32f.size() != size_t(side) * side))
      throw std::runtime_error("raster: the R32F map needs 4^level floats (level <= 14)");
    r32f = dev.image(side, side, VK_FORMAT_R32_SFLOAT, VK_IMAGE_USAGE_SAMPLED_BIT | VK_IMAGE_USAGE_TRANSFER_DST_BIT,
                     VK_IMAGE_ASPECT_COLOR_BIT);
    Buffer staging = dev.buffer(size_t(side) * side * 4, VK_BUFFER_USAGE_TRANSFER_SRC_BIT);
    if (o.r32f.empty()) std::memset(staging.mapped, 0, 4);
    else std::memcpy(staging.mapped, o.r32f.data(), o.r32f.size() * 4);
    VkCommandBuffer cmd = cmds[0];
    VkCommandBufferBeginInfo bi{};
    bi.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO;
    bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
    check(vkBeginCommandBuffer(cmd, &bi), "vkBeginCommandBuffer");
    VkImageMemoryBarrier b{};
    b.sType = VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER;
    b.srcQueueFamilyIndex = b.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
    b.image = r32f.image;
    b.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, 1};
    b.oldLayout = VK_IMAGE_LAYOUT_UNDEFINED;
    b.newLayout = VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL;
    b.dstAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
    vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT, 0, 0, nullptr, 0, nullptr, 1, &b);
    VkBufferImageCopy c{};
    c.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
    c.imageExtent = {side, side, 1};
    vkCmdCopyBufferToImage(cmd, staging.buffer, r32f.image, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, 1, &c);
    b.oldLayout = VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL;
    b.newLayout = VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL;
    b.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
    b.dstAccessMask = VK_ACCESS_SHADER_READ_BIT;
    vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_FRAGMENT_SHADER_BIT, 0, 0, nullptr, 0, nullptr,
                         1, &b);
    check(vkEndCommandBuffer(cmd), "vkEndCommandBuffer");
    VkSubmitInfo si{};
    si.sType = VK_STRUCTURE_TYPE_SUBMIT_INFO;
    si.commandBufferCount = 1;
    si.pCommandBuffers = &cmd;
    check(vkResetFences(dev.device, 1, &fences[0]), "vkResetFences");
    check(vkQueueSubmit(dev.queue, 1, &si, fences[0]), "vkQueueSubmit");
    check(vkWaitForFences(dev.device, 1, &fences[0], VK_TRUE, UINT64_MAX), "vkWaitForFences");  // set-up only
    dev.destroy(staging);
    VkSamplerCreateInfo sci{};
    sci.sType = VK_STRUCTURE_TYPE_SAMPLER_CREATE_INFO;
    sci.magFilter = sci.minFilter = VK_FILTER_NEAREST;
    sci.addressModeU = sci.addressModeV = sci.addressModeW = VK_SAMPLER_ADDRESS_MODE_CLAMP_TO_EDGE;
    check(vkCreateSampler(dev.device, &sci, nullptr, &sampler), "vkCreateSampler");
  }

  void make_passes() {
    // The depth pre-pass: depth only, cleared and stored.
    const VkAttachmentDescription d =
        vk_setup::attachment(VK_FORMAT_D32_SFLOAT, VK_ATTACHMENT_LOAD_OP_CLEAR, VK_ATTACHMENT_STORE_OP_STORE,
                             VK_IMAGE_LAYOUT_UNDEFINED, VK_IMAGE_LAYOUT_DEPTH_STENCIL_ATTACHMENT_OPTIMAL);
    const VkAttachmentReference dref{0, VK_IMAGE_LAYOUT_DEPTH_STENCIL_ATTACHMENT_OPTIMAL};
    VkSubpassDependency dep{};  // the previous frame's shading pass read this depth
    dep.srcSubpass = VK_SUBPASS_EXTERNAL;
    dep.dstSubpass = 0;
    dep.srcStageMask = dep.dstStageMask = VK_PIPELINE_STAGE_EARLY_FRAGMENT_TESTS_BIT | VK_PIPELINE_STAGE_LATE_FRAGMENT_TESTS_BIT;
    dep.srcAccessMask = VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_READ_BIT | VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_WRITE_BIT;
    dep.dstAccessMask = VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_READ_BIT | VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_WRITE_BIT;
    rp_depth = vk_setup::render_pass(dev.setup(), {&d, 1}, {}, &dref, {&dep, 1});
    fb_depth = vk_setup::framebuffer(dev.setup(), rp_depth, {&depth.view, 1}, o.width, o.height);

    // The shading pass: colour (and the twin's receivers and visibility) cleared, depth
    // loaded and tested EQUAL (each pixel's fragment shader runs once).
    VkAttachmentDescription att[4];
    att[0] = vk_setup::attachment(VK_FORMAT_D32_SFLOAT, VK_ATTACHMENT_LOAD_OP_LOAD, VK_ATTACHMENT_STORE_OP_DONT_CARE,
                                  VK_IMAGE_LAYOUT_DEPTH_STENCIL_ATTACHMENT_OPTIMAL,
                                  VK_IMAGE_LAYOUT_DEPTH_STENCIL_ATTACHMENT_OPTIMAL);
    const VkFormat formats[3] = {VK_FORMAT_R8G8B8A8_UNORM, VK_FORMAT_R32G32B32A32_SFLOAT,
                                 VK_FORMAT_R32G32B32A32_SFLOAT};
    for (uint32_t i = 0; i < 3; ++i)
      att[i + 1] = vk_setup::attachment(formats[i], VK_ATTACHMENT_LOAD_OP_CLEAR, VK_ATTACHMENT_STORE_OP_STORE,
                                        VK_IMAGE_LAYOUT_UNDEFINED, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL);
    const uint32_t n = o.twin ? 4 : 2;
    const VkAttachmentReference cref[3] = {{1, VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL},
                                           {2, VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL},
                                           {3, VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL}};
    VkSubpassDependency deps[3] = {};
    deps[0].srcSubpass = VK_SUBPASS_EXTERNAL;  // the pre-pass's depth writes -> this pass's tests
    deps[0].dstSubpass = 0;
    deps[0].srcStageMask = VK_PIPELINE_STAGE_LATE_FRAGMENT_TESTS_BIT;
    deps[0].dstStageMask = VK_PIPELINE_STAGE_EARLY_FRAGMENT_TESTS_BIT | VK_PIPELINE_STAGE_LATE_FRAGMENT_TESTS_BIT;
    deps[0].srcAccessMask = VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_WRITE_BIT;
    deps[0].dstAccessMask = VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_READ_BIT;
    deps[1].srcSubpass = VK_SUBPASS_EXTERNAL;  // the previous frame's copies of the colour
    deps[1].dstSubpass = 0;
    deps[1].srcStageMask = VK_PIPELINE_STAGE_TRANSFER_BIT;
    deps[1].dstStageMask = VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT;
    deps[1].srcAccessMask = 0;
    deps[1].dstAccessMask = VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT;
    deps[2].srcSubpass = 0;  // the attachments' writes -> the copies to the readback buffers
    deps[2].dstSubpass = VK_SUBPASS_EXTERNAL;
    deps[2].srcStageMask = VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT;
    deps[2].dstStageMask = VK_PIPELINE_STAGE_TRANSFER_BIT;
    deps[2].srcAccessMask = VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT;
    deps[2].dstAccessMask = VK_ACCESS_TRANSFER_READ_BIT;
    rp_shade = vk_setup::render_pass(dev.setup(), {att, n}, {cref, n - 1}, &dref, deps);
    const VkImageView views[4] = {depth.view, colour.view, receivers.view, visibility.view};
    fb_shade = vk_setup::framebuffer(dev.setup(), rp_shade, {views, n}, o.width, o.height);
  }

  void make_pipelines() {
    const auto d = dev.setup();
    // Set 0: GpuMap's buffers (shadowtile.glsl), one set per ring slot (its feedback range).
    set_layout = vk_setup::set_layout(d, vk_setup::bindings(3, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, VK_SHADER_STAGE_FRAGMENT_BIT));
    // Set 1: the plain R32F depth map (Lookup::r32f).
    map_layout = vk_setup::set_layout(d, vk_setup::bindings(1, VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER, VK_SHADER_STAGE_FRAGMENT_BIT));
    const VkDescriptorSetLayout both[2] = {set_layout, map_layout};
    layout = vk_setup::pipeline_layout(d, both, {VK_SHADER_STAGE_VERTEX_BIT | VK_SHADER_STAGE_FRAGMENT_BIT, 0, sizeof(Push)});
    const VkDescriptorPoolSize ps[2] = {{VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 3 * o.frames_in_flight},
                                        {VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER, 1}};
    dpool = vk_setup::descriptor_pool(d, o.frames_in_flight + 1, ps);
    sets.resize(o.frames_in_flight);
    for (uint32_t i = 0; i < o.frames_in_flight; ++i) {
      sets[i] = vk_setup::allocate_set(d, dpool, set_layout);
      const gpu::GpuDescriptors g_i = g->descriptors(i);  // ring slot i's feedback (frame f uses slot f % N)
      const VkDescriptorBufferInfo infos[3] = {g_i.pool, g_i.page_table, g_i.feedback};
      vk_setup::write_buffers(d, sets[i], infos);
    }
    map_set = vk_setup::allocate_set(d, dpool, map_layout);
    const VkDescriptorImageInfo ii{sampler, r32f.view, VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL};
    vk_setup::write_images(d, map_set, {&ii, 1});

    const vk_setup::ShaderModule vs(d, kVertSpv), fs(d, o.twin ? std::span<const uint32_t>(kFragTwinSpv)
                                                                : std::span<const uint32_t>(kFragSpv));
    const VkVertexInputBindingDescription vbind{0, 24, VK_VERTEX_INPUT_RATE_VERTEX};
    const VkVertexInputAttributeDescription vattr[2] = {{0, 0, VK_FORMAT_R32G32B32_SFLOAT, 0},
                                                        {1, 0, VK_FORMAT_R32G32B32_SFLOAT, 12}};
    VkPipelineDepthStencilStateCreateInfo ds{};
    ds.sType = VK_STRUCTURE_TYPE_PIPELINE_DEPTH_STENCIL_STATE_CREATE_INFO;
    ds.depthTestEnable = ds.depthWriteEnable = VK_TRUE;
    ds.depthCompareOp = VK_COMPARE_OP_LESS;
    vk_setup::Pipeline p;
    p.layout = layout, p.width = o.width, p.height = o.height;
    p.vertex = vs.module;  // the pre-pass: the vertex shader alone
    p.vertex_bindings = {&vbind, 1}, p.vertex_attributes = vattr;
    p.depth = &ds;
    p.pass = rp_depth;
    depth_pipeline = vk_setup::pipeline(d, p);
    ds.depthWriteEnable = VK_FALSE;
    ds.depthCompareOp = VK_COMPARE_OP_EQUAL;  // gl_Position is invariant: the same depths
    p.fragment = fs.module;
    // scene.frag's ST_MAP_KIND_ID: the map's kind, so the pipeline holds one kind's tile walk.
    const uint32_t map_kind = g->is_stack() ? 2u : 1u;
    const VkSpecializationMapEntry kind_entry{0, 0, sizeof(uint32_t)};
    const VkSpecializationInfo spec{1, &kind_entry, sizeof(map_kind), &map_kind};
    p.fragment_specialization = &spec;
    p.colour_attachments = o.twin ? 3 : 1;
    p.pass = rp_shade;
    shade_pipeline = vk_setup::pipeline(d, p);
  }

  double stamp_ms(const uint64_t* t, int a, int b) const {
    if (!queries) return 0;
    const uint64_t mask = dev.timestamp_bits >= 64 ? ~uint64_t(0) : (uint64_t(1) << dev.timestamp_bits) - 1;
    return double((t[b] - t[a]) & mask) * double(dev.props.limits.timestampPeriod) * 1e-6;
  }

  // Collects slot s's finished frame into `done` (its pixels copied out, its timestamps read).
  void collect(uint32_t s) {
    Slot& sl = slots[s];
    FrameResult r;
    r.frame = sl.frame;
    r.host_us = sl.host_us, r.retire_us = sl.retire_us, r.uploads_us = sl.uploads_us;
    if (queries) {
      uint64_t t[kStamps] = {};
      check(vkGetQueryPoolResults(dev.device, queries, s * kStamps, kStamps, sizeof(t), t, sizeof(uint64_t),
                                  VK_QUERY_RESULT_64_BIT),
            "vkGetQueryPoolResults");
      r.gpu_upload_ms = stamp_ms(t, 0, 1);
      r.gpu_depth_ms = stamp_ms(t, 1, 2);
      r.gpu_shade_ms = stamp_ms(t, 2, 3);
      r.gpu_frame_ms = stamp_ms(t, 0, 4);
    }
    const size_t pixels = size_t(o.width) * o.height;
    if (o.readback) {
      const auto* p = static_cast<const uint8_t*>(sl.rgba.mapped);
      done_rgba.emplace_back(p, p + pixels * 4);
    }
    if (o.twin) {
      const auto* rc = static_cast<const float*>(sl.rec.mapped);
      const auto* vs = static_cast<const float*>(sl.vis.mapped);
      done_rec.emplace_back(rc, rc + pixels * 4);
      // The shader's (visibility, gx, gy, 0) per pixel: split into the two spans.
      std::vector<float>& v = done_vis.emplace_back(pixels);
      std::vector<float>& g = done_slopes.emplace_back(2 * pixels);
      for (size_t i = 0; i < pixels; ++i) v[i] = vs[4 * i], g[2 * i] = vs[4 * i + 1], g[2 * i + 1] = vs[4 * i + 2];
    }
    done.push_back(r);
    completed = std::max(completed, sl.frame);
    sl.frame = 0;
  }

  // Every slot whose fence has signalled (polled), oldest frame first; then GpuMap's retire.
  void retire(bool wait_all, int must_free) {
    done.clear(), done_rgba.clear(), done_rec.clear(), done_vis.clear(), done_slopes.clear();
    std::vector<uint32_t> order;
    for (uint32_t s = 0; s < slots.size(); ++s)
      if (slots[s].frame) order.push_back(s);
    std::sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return slots[a].frame < slots[b].frame; });
    for (uint32_t s : order) {
      VkResult st = vkGetFenceStatus(dev.device, fences[s]);
      if (st == VK_NOT_READY && (wait_all || int(s) == must_free)) {
        if (!wait_all) ++waits;
        st = vkWaitForFences(dev.device, 1, &fences[s], VK_TRUE, UINT64_MAX);
      }
      if (st == VK_NOT_READY) break;  // frames complete in order: later ones are running too
      check(st, "vkGetFenceStatus");
      collect(s);
    }
    const auto t0 = Clock::now();
    const std::span<const gpu::FrameStats> fs = g->retire(completed);
    retire_us = us_since(t0);
    for (const gpu::FrameStats& x : fs)
      for (FrameResult& r : done)
        if (r.frame == x.frame) r.stats = x;
    for (size_t i = 0; i < done.size(); ++i) {
      if (o.readback) done[i].rgba = done_rgba[i];
      if (o.twin) done[i].receivers = done_rec[i], done[i].visibility = done_vis[i], done[i].slopes = done_slopes[i];
    }
  }

  void copy_out(VkCommandBuffer cmd, const Image& im, const Buffer& to) {
    VkBufferImageCopy c{};
    c.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
    c.imageExtent = {o.width, o.height, 1};
    vkCmdCopyImageToBuffer(cmd, im.image, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, to.buffer, 1, &c);
  }

  void render(const FrameInput& in) {
    if (in.kernel < 1 || in.kernel > 9) throw std::runtime_error("raster: PCF kernel side 1..9");
    const uint64_t f = ++frame;
    const uint32_t s = uint32_t(f % slots.size());
    retire(false, int(s));
    Slot& sl = slots[s];
    VkCommandBuffer cmd = cmds[s];
    check(vkResetFences(dev.device, 1, &fences[s]), "vkResetFences");
    check(vkResetCommandBuffer(cmd, 0), "vkResetCommandBuffer");
    // Partial occluders (a pack's deep part): the fragment shader multiplies their
    // transmittance in (st_transmittance) and feeds back the deep tiles it lacked, as it
    // does opaque ones: nothing to ask for here.
    VkCommandBufferBeginInfo bi{};
    bi.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO;
    bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
    check(vkBeginCommandBuffer(cmd, &bi), "vkBeginCommandBuffer");
    if (queries) {
      vkCmdResetQueryPool(cmd, queries, s * kStamps, kStamps);
      vkCmdWriteTimestamp(cmd, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, queries, s * kStamps + 0);
    }
    auto t0 = Clock::now();
    g->record_uploads(cmd, f);
    sl.uploads_us = us_since(t0);
    sl.retire_us = retire_us;
    sl.host_us = sl.uploads_us + retire_us;
    if (queries) vkCmdWriteTimestamp(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, queries, s * kStamps + 1);

    // Near and far planes around the scene's box.
    double far = 0;
    for (int c = 0; c < 8; ++c) {
      const double p[3] = {c & 1 ? hi[0] : lo[0], c & 2 ? hi[1] : lo[1], c & 4 ? hi[2] : lo[2]};
      far = std::max(far, std::hypot(p[0] - in.eye[0], p[1] - in.eye[1], p[2] - in.eye[2]));
    }
    far = far * 1.01 + 1e-6;
    Push push{};
    push.view_projection = vulkan_view_projection(in, double(o.width) / o.height, far * 1e-4, far);
    for (int k = 0; k < 3; ++k) push.light[k] = float(in.light[k]), push.eye[k] = float(in.eye[k]);
    push.light[3] = in.light_is_point ? 1.0f : 0.0f;
    // One pixel's angle (as `render --filter` measures it): the footprint's level pair.
    push.eye[3] = in.filter ? float(2 * std::tan(in.fov_deg * 3.14159265358979323846 / 360) / o.height) : 0.0f;
    push.mode[0] = uint32_t(in.lookup);
    push.mode[1] = in.kernel;
    push.mode[2] = (in.slice_a & 0xFFFFu) | (in.slice_b << 16);
    push.mode[3] = in.soft ? 1u : 0u;
    push.misc[0] = in.blend;
    push.misc[1] = float(in.texel);
    push.misc[2] = float(1.5 + (in.kernel - 1) / 2.0);  // `render`'s open-receiver offset plus the PCF radius
    push.misc[3] = 1.5f;  // filtered: render's kOpenReceiverOffsetTexels alone (the receiver plane does the rest)

    VkClearValue clear[4] = {};
    clear[0].depthStencil = {1.0f, 0};
    // `render`'s sky (0.55, 0.7, 0.9) with its PNG's gamma, as the shader writes its colour.
    clear[1].color = {{std::pow(0.55f, 1 / 2.2f), std::pow(0.7f, 1 / 2.2f), std::pow(0.9f, 1 / 2.2f), 1.0f}};
    clear[2].color = {{0, 0, 0, -1.0f}};
    clear[3].color = {{1.0f, 0, 0, 0}};
    const VkDeviceSize zero = 0;
    VkRenderPassBeginInfo rbi{};
    rbi.sType = VK_STRUCTURE_TYPE_RENDER_PASS_BEGIN_INFO;
    rbi.renderPass = rp_depth;
    rbi.framebuffer = fb_depth;
    rbi.renderArea = {{0, 0}, {o.width, o.height}};
    rbi.clearValueCount = 1;
    rbi.pClearValues = clear;
    vkCmdBeginRenderPass(cmd, &rbi, VK_SUBPASS_CONTENTS_INLINE);
    vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_GRAPHICS, depth_pipeline);
    vkCmdPushConstants(cmd, layout, VK_SHADER_STAGE_VERTEX_BIT | VK_SHADER_STAGE_FRAGMENT_BIT, 0, sizeof(push), &push);
    vkCmdBindVertexBuffers(cmd, 0, 1, &vb.buffer, &zero);
    vkCmdDraw(cmd, vertex_count, 1, 0, 0);
    vkCmdEndRenderPass(cmd);
    if (queries) vkCmdWriteTimestamp(cmd, VK_PIPELINE_STAGE_LATE_FRAGMENT_TESTS_BIT, queries, s * kStamps + 2);

    rbi.renderPass = rp_shade;
    rbi.framebuffer = fb_shade;
    rbi.clearValueCount = o.twin ? 4 : 2;
    vkCmdBeginRenderPass(cmd, &rbi, VK_SUBPASS_CONTENTS_INLINE);
    vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_GRAPHICS, shade_pipeline);
    const VkDescriptorSet both[2] = {sets[s], map_set};
    vkCmdBindDescriptorSets(cmd, VK_PIPELINE_BIND_POINT_GRAPHICS, layout, 0, 2, both, 0, nullptr);
    vkCmdPushConstants(cmd, layout, VK_SHADER_STAGE_VERTEX_BIT | VK_SHADER_STAGE_FRAGMENT_BIT, 0, sizeof(push), &push);
    vkCmdBindVertexBuffers(cmd, 0, 1, &vb.buffer, &zero);
    vkCmdDraw(cmd, vertex_count, 1, 0, 0);
    vkCmdEndRenderPass(cmd);
    if (queries) vkCmdWriteTimestamp(cmd, VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT, queries, s * kStamps + 3);

    if (o.readback) copy_out(cmd, colour, sl.rgba);
    if (o.twin) copy_out(cmd, receivers, sl.rec), copy_out(cmd, visibility, sl.vis);
    VkMemoryBarrier mb{};
    mb.sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER;
    mb.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
    mb.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
    vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_HOST_BIT, 0, 1, &mb, 0, nullptr, 0, nullptr);
    if (queries) vkCmdWriteTimestamp(cmd, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, queries, s * kStamps + 4);
    t0 = Clock::now();
    g->record_end_of_frame(cmd, f);
    sl.host_us += us_since(t0);
    check(vkEndCommandBuffer(cmd), "vkEndCommandBuffer");
    VkSubmitInfo si{};
    si.sType = VK_STRUCTURE_TYPE_SUBMIT_INFO;
    si.commandBufferCount = 1;
    si.pCommandBuffers = &cmd;
    check(vkQueueSubmit(dev.queue, 1, &si, fences[s]), "vkQueueSubmit");
    sl.frame = f;
  }
};

Rasterizer::Rasterizer(client::Map map, std::span<const float> triangles, const RasterOptions& options)
    : impl_(std::make_unique<Impl>(std::move(map), triangles, options)) {}
Rasterizer::~Rasterizer() = default;

std::span<const FrameResult> Rasterizer::render(const FrameInput& in) {
  impl_->render(in);
  return impl_->done;
}
std::span<const FrameResult> Rasterizer::finish() {
  impl_->retire(true, -1);
  return impl_->done;
}
void Rasterizer::wait_idle() {
  Impl& m = *impl_;
  for (uint32_t s = 0; s < m.slots.size(); ++s)
    if (m.slots[s].frame) check(vkWaitForFences(m.dev.device, 1, &m.fences[s], VK_TRUE, UINT64_MAX), "vkWaitForFences");
}
uint64_t Rasterizer::frames() const { return impl_->frame; }
uint64_t Rasterizer::ring_waits() const { return impl_->waits; }
uint64_t Rasterizer::validation_messages() const { return impl_->dev.messages(); }
const std::string& Rasterizer::first_validation_message() const { return impl_->dev.first_message(); }
double Rasterizer::retire_host_us_last() const { return impl_->retire_us; }
const std::string& Rasterizer::device_name() const { return impl_->dev.name; }
gpu::GpuStats Rasterizer::stats() const { return impl_->g->stats(); }
uint32_t Rasterizer::width() const { return impl_->o.width; }
uint32_t Rasterizer::height() const { return impl_->o.height; }

}  // namespace st::raster
