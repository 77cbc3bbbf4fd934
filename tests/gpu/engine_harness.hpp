// A tiny engine for the engine-mode tests: it owns what a game's renderer owns (instance
// with the Khronos validation layer and a messenger counting errors and warnings, the
// lavapipe device with a graphics + compute queue, command buffers and fences per frame in
// flight, G-buffer and visibility images) and hands GpuMap only an EngineDevice. It
// submits and waits as an engine does: frame f waits for frame f - frames_in_flight's
// fence before reusing its command buffer, and tells GpuMap which frame completed.
// The loaders given to GpuMap count their calls, so a test can see they were used.
#pragma once
#include <vulkan/vulkan.h>

#include <atomic>
#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

#include "gpu/gpu_map.hpp"
#include "shadowtile/vk_setup.hpp"
#include "tests/gpu/gpu_test_util.hpp"

namespace st::enginetest {

inline void check(VkResult r, const char* what) {
  if (r != VK_SUCCESS) throw std::runtime_error(std::string("test engine: ") + what + " failed: " + std::to_string(int(r)));
}

inline std::atomic<uint64_t> g_instance_lookups{0}, g_device_lookups{0};
inline VKAPI_ATTR PFN_vkVoidFunction VKAPI_CALL counting_gipa(VkInstance i, const char* name) {
  ++g_instance_lookups;
  return vkGetInstanceProcAddr(i, name);
}
inline VKAPI_ATTR PFN_vkVoidFunction VKAPI_CALL counting_gdpa(VkDevice d, const char* name) {
  ++g_device_lookups;
  return vkGetDeviceProcAddr(d, name);
}

// An engine-side GpuAllocator (what a VMA user writes): counts live buffers.
class CountingAllocator final : public gpu::GpuAllocator {
 public:
  CountingAllocator(VkDevice d, VkPhysicalDevice p) : device_(d) { vkGetPhysicalDeviceMemoryProperties(p, &mem_); }
  VkResult create_buffer(const VkBufferCreateInfo& info, gpu::BufferUse use, gpu::GpuBuffer& out) override {
    out = {};
    const bool host = use != gpu::BufferUse::device_local;
    const VkMemoryPropertyFlags want = host ? VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT
                                            : VkMemoryPropertyFlags(VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
    vk_setup::Buffer b;
    const VkResult r = vk_setup::create_buffer(setup(), mem_, info, want, want, host, b);
    if (r != VK_SUCCESS) return r;
    out.buffer = b.buffer;
    out.mapped = b.mapped;
    out.allocation = reinterpret_cast<void*>(b.memory);
    out.size = info.size;
    ++live;
    ++created;
    return VK_SUCCESS;
  }
  void destroy_buffer(gpu::GpuBuffer& b) noexcept override {
    vk_setup::Buffer own{b.buffer, reinterpret_cast<VkDeviceMemory>(b.allocation), b.mapped};
    vk_setup::destroy(setup(), own);
    b = {};
    --live;
  }
  vk_setup::Device<vk_setup::Loader> setup() const { return {vk_setup::kLoader, device_}; }
  const VkPhysicalDeviceMemoryProperties& memory() const { return mem_; }
  int live = 0, created = 0;

 private:
  VkDevice device_;
  VkPhysicalDeviceMemoryProperties mem_{};
};

struct Image : vk_setup::Image {
  VkFormat format = VK_FORMAT_UNDEFINED;
  uint32_t width = 0, height = 0;
};

class TestEngine {
 public:
  explicit TestEngine(uint32_t frames_in_flight) : n_(frames_in_flight) {
    VkApplicationInfo app{};
    app.sType = VK_STRUCTURE_TYPE_APPLICATION_INFO;
    app.apiVersion = VK_API_VERSION_1_2;
    const char* layer = "VK_LAYER_KHRONOS_validation";
    const char* ext = VK_EXT_DEBUG_UTILS_EXTENSION_NAME;
    VkDebugUtilsMessengerCreateInfoEXT dbg{};
    dbg.sType = VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT;
    dbg.messageSeverity = VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT;
    dbg.messageType = VK_DEBUG_UTILS_MESSAGE_TYPE_GENERAL_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT |
                      VK_DEBUG_UTILS_MESSAGE_TYPE_PERFORMANCE_BIT_EXT;
    dbg.pfnUserCallback = &TestEngine::on_message;
    dbg.pUserData = this;
    VkInstanceCreateInfo ici{};
    ici.sType = VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO;
    ici.pNext = &dbg;
    ici.pApplicationInfo = &app;
    ici.enabledLayerCount = 1;
    ici.ppEnabledLayerNames = &layer;
    ici.enabledExtensionCount = 1;
    ici.ppEnabledExtensionNames = &ext;
    check(vkCreateInstance(&ici, nullptr, &instance), "vkCreateInstance");
    auto create = reinterpret_cast<PFN_vkCreateDebugUtilsMessengerEXT>(
        vkGetInstanceProcAddr(instance, "vkCreateDebugUtilsMessengerEXT"));
    check(create(instance, &dbg, nullptr, &messenger_), "vkCreateDebugUtilsMessengerEXT");
    uint32_t count = 0;
    vkEnumeratePhysicalDevices(instance, &count, nullptr);
    std::vector<VkPhysicalDevice> devs(count);
    vkEnumeratePhysicalDevices(instance, &count, devs.data());
    for (VkPhysicalDevice d : devs) {
      VkPhysicalDeviceProperties p{};
      vkGetPhysicalDeviceProperties(d, &p);
      if (std::strstr(p.deviceName, gputest::device().c_str())) physical = d;
    }
    if (!physical) throw std::runtime_error("test engine: no device named like " + gputest::device());
    uint32_t qn = 0;
    vkGetPhysicalDeviceQueueFamilyProperties(physical, &qn, nullptr);
    std::vector<VkQueueFamilyProperties> qs(qn);
    vkGetPhysicalDeviceQueueFamilyProperties(physical, &qn, qs.data());
    family = ~0u;
    for (uint32_t i = 0; i < qn && family == ~0u; ++i)
      if ((qs[i].queueFlags & (VK_QUEUE_GRAPHICS_BIT | VK_QUEUE_COMPUTE_BIT)) == (VK_QUEUE_GRAPHICS_BIT | VK_QUEUE_COMPUTE_BIT))
        family = i;
    if (family == ~0u) throw std::runtime_error("test engine: no graphics + compute queue");
    const float prio = 1;
    VkDeviceQueueCreateInfo qci{};
    qci.sType = VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO;
    qci.queueFamilyIndex = family;
    qci.queueCount = 1;
    qci.pQueuePriorities = &prio;
    VkPhysicalDeviceFeatures have{}, want{};
    vkGetPhysicalDeviceFeatures(physical, &have);
    want.fragmentStoresAndAtomics = have.fragmentStoresAndAtomics;
    fragment_stores = have.fragmentStoresAndAtomics;
    VkDeviceCreateInfo dci{};
    dci.sType = VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO;
    dci.queueCreateInfoCount = 1;
    dci.pQueueCreateInfos = &qci;
    dci.pEnabledFeatures = &want;
    check(vkCreateDevice(physical, &dci, nullptr, &device), "vkCreateDevice");
    vkGetDeviceQueue(device, family, 0, &queue);
    const vk_setup::Device<vk_setup::Loader> v{vk_setup::kLoader, device};
    pool_ = vk_setup::command_pool(v, family, true);
    cmds_.resize(n_);
    vk_setup::command_buffers(v, pool_, cmds_);
    fences_.resize(n_);
    submitted_.assign(n_, 0);
    for (VkFence& f : fences_) f = vk_setup::fence(v, true);
  }

  ~TestEngine() {
    vkDeviceWaitIdle(device);
    for (Image* i : images_) destroy(*i);
    for (VkFence f : fences_) vkDestroyFence(device, f, nullptr);
    vkDestroyCommandPool(device, pool_, nullptr);
    vkDestroyDevice(device, nullptr);
    auto destroy_messenger = reinterpret_cast<PFN_vkDestroyDebugUtilsMessengerEXT>(
        vkGetInstanceProcAddr(instance, "vkDestroyDebugUtilsMessengerEXT"));
    destroy_messenger(instance, messenger_, nullptr);
    vkDestroyInstance(instance, nullptr);
  }
  TestEngine(const TestEngine&) = delete;
  TestEngine& operator=(const TestEngine&) = delete;

  gpu::EngineDevice engine_device(gpu::GpuAllocator* allocator = nullptr) const {
    gpu::EngineDevice d;
    d.instance = instance;
    d.physical_device = physical;
    d.device = device;
    d.queue_family = family;
    d.get_instance_proc_addr = &counting_gipa;
    d.get_device_proc_addr = &counting_gdpa;
    d.allocator = allocator;
    return d;
  }

  // Frame f: waits for frame f - n (its slot's fence), begins the slot's command buffer.
  // Returns the newest frame known complete (what the engine tells GpuMap::retire).
  VkCommandBuffer begin(uint64_t frame, uint64_t& completed) {
    const uint32_t s = uint32_t(frame % n_);
    check(vkWaitForFences(device, 1, &fences_[s], VK_TRUE, UINT64_MAX), "vkWaitForFences");
    check(vkResetFences(device, 1, &fences_[s]), "vkResetFences");
    if (submitted_[s] > completed_) completed_ = submitted_[s];
    completed = completed_;
    VkCommandBufferBeginInfo bi{};
    bi.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO;
    bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
    check(vkResetCommandBuffer(cmds_[s], 0), "vkResetCommandBuffer");
    check(vkBeginCommandBuffer(cmds_[s], &bi), "vkBeginCommandBuffer");
    return cmds_[s];
  }
  void submit(uint64_t frame) {
    const uint32_t s = uint32_t(frame % n_);
    check(vkEndCommandBuffer(cmds_[s]), "vkEndCommandBuffer");
    VkSubmitInfo si{};
    si.sType = VK_STRUCTURE_TYPE_SUBMIT_INFO;
    si.commandBufferCount = 1;
    si.pCommandBuffers = &cmds_[s];
    check(vkQueueSubmit(queue, 1, &si, fences_[s]), "vkQueueSubmit");
    submitted_[s] = frame;
  }
  // Waits for everything submitted; returns the newest frame.
  uint64_t finish() {
    check(vkQueueWaitIdle(queue), "vkQueueWaitIdle");
    for (uint64_t f : submitted_) completed_ = std::max(completed_, f);
    return completed_;
  }

  // A one-off command buffer for the test's own setup and readback (not the frame path).
  template <class Fn>
  void once(Fn&& fn) {
    VkCommandBuffer cmd = VK_NULL_HANDLE;
    vk_setup::command_buffers(vk_setup::Device<vk_setup::Loader>{vk_setup::kLoader, device}, pool_, {&cmd, 1});
    VkCommandBufferBeginInfo bi{};
    bi.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO;
    bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
    vkBeginCommandBuffer(cmd, &bi);
    fn(cmd);
    vkEndCommandBuffer(cmd);
    VkSubmitInfo si{};
    si.sType = VK_STRUCTURE_TYPE_SUBMIT_INFO;
    si.commandBufferCount = 1;
    si.pCommandBuffers = &cmd;
    check(vkQueueSubmit(queue, 1, &si, VK_NULL_HANDLE), "vkQueueSubmit");
    check(vkQueueWaitIdle(queue), "vkQueueWaitIdle");
    vkFreeCommandBuffers(device, pool_, 1, &cmd);
  }

  // A 2D image with a view; `usage` plus transfer src and dst. Destroyed with the engine.
  Image& image(uint32_t w, uint32_t h, VkFormat format, VkImageUsageFlags usage) {
    auto* im = new Image{};
    images_.push_back(im);
    im->format = format, im->width = w, im->height = h;
    CountingAllocator memory(device, physical);
    check(vk_setup::create_image(memory.setup(), memory.memory(), w, h, format,
                                 usage | VK_IMAGE_USAGE_TRANSFER_SRC_BIT | VK_IMAGE_USAGE_TRANSFER_DST_BIT,
                                 VK_IMAGE_ASPECT_COLOR_BIT, *im),
          "creating an image");
    return *im;
  }

  static void layout(VkCommandBuffer cmd, const Image& im, VkImageLayout from, VkImageLayout to, VkPipelineStageFlags src,
                     VkAccessFlags src_access, VkPipelineStageFlags dst, VkAccessFlags dst_access) {
    VkImageMemoryBarrier b{};
    b.sType = VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER;
    b.oldLayout = from;
    b.newLayout = to;
    b.srcAccessMask = src_access;
    b.dstAccessMask = dst_access;
    b.srcQueueFamilyIndex = b.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
    b.image = im.image;
    b.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, 1};
    vkCmdPipelineBarrier(cmd, src, dst, 0, 0, nullptr, 0, nullptr, 1, &b);
  }

  // Host floats (4 per texel for RGBA32F, 1 for R32F) into the image, left in `final`.
  void upload(Image& im, const std::vector<float>& data, VkImageLayout final) {
    gpu::GpuBuffer staging = host_buffer(data.size() * 4);
    std::memcpy(staging.mapped, data.data(), data.size() * 4);
    once([&](VkCommandBuffer cmd) {
      layout(cmd, im, VK_IMAGE_LAYOUT_UNDEFINED, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, 0,
             VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT);
      VkBufferImageCopy c{};
      c.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
      c.imageExtent = {im.width, im.height, 1};
      vkCmdCopyBufferToImage(cmd, staging.buffer, im.image, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, 1, &c);
      layout(cmd, im, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, final, VK_PIPELINE_STAGE_TRANSFER_BIT,
             VK_ACCESS_TRANSFER_WRITE_BIT, VK_PIPELINE_STAGE_ALL_COMMANDS_BIT, VK_ACCESS_SHADER_READ_BIT);
    });
    free_host_buffer(staging);
  }

  // Records the copy of an R32F image (layout `from`, written at `stage` with `access`)
  // into a host buffer, and the barrier making it host-visible.
  void record_readback(VkCommandBuffer cmd, const Image& im, VkImageLayout from, VkPipelineStageFlags stage,
                       const gpu::GpuBuffer& dst, VkAccessFlags access = VK_ACCESS_SHADER_WRITE_BIT) {
    layout(cmd, im, from, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, stage, access, VK_PIPELINE_STAGE_TRANSFER_BIT,
           VK_ACCESS_TRANSFER_READ_BIT);
    VkBufferImageCopy c{};
    c.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
    c.imageExtent = {im.width, im.height, 1};
    vkCmdCopyImageToBuffer(cmd, im.image, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, dst.buffer, 1, &c);
    layout(cmd, im, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, from, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_READ_BIT,
           stage, access);
    VkMemoryBarrier mb{};
    mb.sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER;
    mb.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
    mb.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
    vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_HOST_BIT, 0, 1, &mb, 0, nullptr, 0, nullptr);
  }

  gpu::GpuBuffer host_buffer(VkDeviceSize bytes) {
    CountingAllocator a(device, physical);
    VkBufferCreateInfo bci{};
    bci.sType = VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO;
    bci.size = bytes;
    bci.usage = VK_BUFFER_USAGE_TRANSFER_SRC_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT;
    gpu::GpuBuffer b;
    check(a.create_buffer(bci, gpu::BufferUse::readback, b), "host buffer");
    return b;
  }
  void free_host_buffer(gpu::GpuBuffer& b) {
    CountingAllocator a(device, physical);
    a.destroy_buffer(b);
  }

  uint64_t messages() const { return messages_.load(); }
  const std::string& first_message() const { return first_; }

  VkInstance instance = VK_NULL_HANDLE;
  VkPhysicalDevice physical = VK_NULL_HANDLE;
  VkDevice device = VK_NULL_HANDLE;
  VkQueue queue = VK_NULL_HANDLE;
  uint32_t family = 0;
  bool fragment_stores = false;

 private:
  static VKAPI_ATTR VkBool32 VKAPI_CALL on_message(VkDebugUtilsMessageSeverityFlagBitsEXT,
                                                   VkDebugUtilsMessageTypeFlagsEXT,
                                                   const VkDebugUtilsMessengerCallbackDataEXT* data, void* self) {
    auto* e = static_cast<TestEngine*>(self);
    if (e->messages_.fetch_add(1) == 0) e->first_ = data && data->pMessage ? data->pMessage : "";
    return VK_FALSE;
  }
  void destroy(Image& im) {
    vk_setup::destroy(vk_setup::Device<vk_setup::Loader>{vk_setup::kLoader, device}, static_cast<vk_setup::Image&>(im));
    delete &im;
  }

  uint32_t n_;
  VkDebugUtilsMessengerEXT messenger_ = VK_NULL_HANDLE;
  VkCommandPool pool_ = VK_NULL_HANDLE;
  std::vector<VkCommandBuffer> cmds_;
  std::vector<VkFence> fences_;
  std::vector<uint64_t> submitted_;
  uint64_t completed_ = 0;
  std::atomic<uint64_t> messages_{0};
  std::string first_;
  std::vector<Image*> images_;
};

// The engine's side of a shadow pass: G-buffer images, the visibility image (GENERAL) and
// one host readback buffer per frame in flight.
struct Targets {
  enginetest::Image *pos = nullptr, *nrm = nullptr, *vis = nullptr;
  std::vector<gpu::GpuBuffer> readback;
  TestEngine& e;
  Targets(TestEngine& engine, uint32_t width, uint32_t height, const std::vector<float>& positions,
          const std::vector<float>& normals, uint32_t frames)
      : e(engine) {
    pos = &e.image(width, height, VK_FORMAT_R32G32B32A32_SFLOAT, VK_IMAGE_USAGE_SAMPLED_BIT);
    nrm = &e.image(width, height, VK_FORMAT_R32G32B32A32_SFLOAT, VK_IMAGE_USAGE_SAMPLED_BIT);
    vis = &e.image(width, height, VK_FORMAT_R32_SFLOAT, VK_IMAGE_USAGE_STORAGE_BIT | VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT);
    e.upload(*pos, positions, VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL);
    e.upload(*nrm, normals, VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL);
    e.upload(*vis, std::vector<float>(size_t(width) * height, -1.0f), VK_IMAGE_LAYOUT_GENERAL);
    for (uint32_t i = 0; i < frames; ++i) readback.push_back(e.host_buffer(size_t(width) * height * 4));
  }
  Targets(const Targets&) = delete;
  Targets& operator=(const Targets&) = delete;
  ~Targets() {
    for (gpu::GpuBuffer& b : readback) e.free_host_buffer(b);
  }
  gpu::ShadowPassImages images() const {
    gpu::ShadowPassImages im;
    im.positions = pos->view;
    im.normals = nrm->view;
    im.visibility = vis->view;
    im.width = pos->width;
    im.height = pos->height;
    return im;
  }
  std::vector<float> read(uint64_t frame) const {
    const gpu::GpuBuffer& b = readback[frame % readback.size()];
    const auto* f = static_cast<const float*>(b.mapped);
    return std::vector<float>(f, f + size_t(pos->width) * pos->height);
  }
};

// One engine frame: retire what completed, uploads, the pass, its readback (the test's
// own), the end-of-frame barrier, submit. Returns record_uploads' stats.
inline gpu::FrameStats run_frame(TestEngine& e, gpu::GpuMap& g, Targets& t, uint64_t frame, const gpu::ShadowPassSettings& s,
                     std::vector<gpu::FrameStats>* retired = nullptr) {
  uint64_t completed = 0;
  VkCommandBuffer cmd = e.begin(frame, completed);
  for (const gpu::FrameStats& r : g.retire(completed))
    if (retired) retired->push_back(r);
  const gpu::FrameStats up = g.record_uploads(cmd, frame);
  g.record_shadow_pass(cmd, frame, t.images(), s);
  e.record_readback(cmd, *t.vis, VK_IMAGE_LAYOUT_GENERAL, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
                    t.readback[frame % t.readback.size()]);
  g.record_end_of_frame(cmd, frame);
  e.submit(frame);
  return up;
}

}  // namespace st::enginetest
