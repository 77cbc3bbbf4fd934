#include "gpu/vk_context.hpp"

#include <cstdlib>
#include <cstring>

namespace st::gpu {

const char* vk_result_name(VkResult r) {
  switch (r) {
#define ST_VK_CASE(x) \
  case x:             \
    return #x;
    ST_VK_CASE(VK_SUCCESS)
    ST_VK_CASE(VK_NOT_READY)
    ST_VK_CASE(VK_TIMEOUT)
    ST_VK_CASE(VK_INCOMPLETE)
    ST_VK_CASE(VK_ERROR_OUT_OF_HOST_MEMORY)
    ST_VK_CASE(VK_ERROR_OUT_OF_DEVICE_MEMORY)
    ST_VK_CASE(VK_ERROR_INITIALIZATION_FAILED)
    ST_VK_CASE(VK_ERROR_DEVICE_LOST)
    ST_VK_CASE(VK_ERROR_MEMORY_MAP_FAILED)
    ST_VK_CASE(VK_ERROR_LAYER_NOT_PRESENT)
    ST_VK_CASE(VK_ERROR_EXTENSION_NOT_PRESENT)
    ST_VK_CASE(VK_ERROR_FEATURE_NOT_PRESENT)
    ST_VK_CASE(VK_ERROR_INCOMPATIBLE_DRIVER)
    ST_VK_CASE(VK_ERROR_TOO_MANY_OBJECTS)
    ST_VK_CASE(VK_ERROR_FORMAT_NOT_SUPPORTED)
    ST_VK_CASE(VK_ERROR_UNKNOWN)
#undef ST_VK_CASE
    default:
      return "VkResult";
  }
}

void vk_check(VkResult r, const char* call) {
  if (r != VK_SUCCESS)
    throw GpuError(std::string("Vulkan: ") + call + " failed: " + vk_result_name(r) + " (" + std::to_string(int(r)) + ")");
}

VKAPI_ATTR VkBool32 VKAPI_CALL VkContext::on_message(VkDebugUtilsMessageSeverityFlagBitsEXT severity,
                                                     VkDebugUtilsMessageTypeFlagsEXT,
                                                     const VkDebugUtilsMessengerCallbackDataEXT* data, void* self) {
  if (severity & (VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT)) {
    auto* c = static_cast<VkContext*>(self);
    if (c->messages_.fetch_add(1) == 0) {
      std::lock_guard lock(c->message_mu_);
      c->first_message_ = data && data->pMessage ? data->pMessage : "(no text)";
    }
  }
  return VK_FALSE;
}

std::string VkContext::first_validation_message() const {
  std::lock_guard lock(message_mu_);
  return first_message_;
}

VkContext::VkContext(const std::string& device_name, bool validation) {
  try {
    VkApplicationInfo app{};
    app.sType = VK_STRUCTURE_TYPE_APPLICATION_INFO;
    app.pApplicationName = "shadowtile";
    app.pEngineName = "shadowtile";
    app.apiVersion = VK_API_VERSION_1_2;
    std::vector<const char*> layers, extensions;
    VkDebugUtilsMessengerCreateInfoEXT dbg{};
    dbg.sType = VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT;
    dbg.messageSeverity = VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT;
    dbg.messageType = VK_DEBUG_UTILS_MESSAGE_TYPE_GENERAL_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT |
                      VK_DEBUG_UTILS_MESSAGE_TYPE_PERFORMANCE_BIT_EXT;
    dbg.pfnUserCallback = &VkContext::on_message;
    dbg.pUserData = this;
    if (validation) {
      uint32_t n = 0;
      vk_check(vkEnumerateInstanceLayerProperties(&n, nullptr), "vkEnumerateInstanceLayerProperties");
      std::vector<VkLayerProperties> have(n);
      vk_check(vkEnumerateInstanceLayerProperties(&n, have.data()), "vkEnumerateInstanceLayerProperties");
      bool found = false;
      for (const auto& l : have) found |= std::strcmp(l.layerName, "VK_LAYER_KHRONOS_validation") == 0;
      if (!found) throw GpuError("Vulkan: validation asked for but VK_LAYER_KHRONOS_validation is not installed (vulkan-validationlayers)");
      layers.push_back("VK_LAYER_KHRONOS_validation");
      extensions.push_back(VK_EXT_DEBUG_UTILS_EXTENSION_NAME);
    }
    VkInstanceCreateInfo ici{};
    ici.sType = VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO;
    ici.pApplicationInfo = &app;
    ici.enabledLayerCount = uint32_t(layers.size());
    ici.ppEnabledLayerNames = layers.data();
    ici.enabledExtensionCount = uint32_t(extensions.size());
    ici.ppEnabledExtensionNames = extensions.data();
    if (validation) ici.pNext = &dbg;
    const VkResult ir = vkCreateInstance(&ici, nullptr, &instance_);
    if (ir == VK_ERROR_INCOMPATIBLE_DRIVER || ir == VK_ERROR_INITIALIZATION_FAILED)
      throw GpuError(std::string("Vulkan: no Vulkan driver found (vkCreateInstance: ") + vk_result_name(ir) +
                     "); install one, e.g. mesa-vulkan-drivers for lavapipe");
    vk_check(ir, "vkCreateInstance");
    if (validation) {
      auto create = reinterpret_cast<PFN_vkCreateDebugUtilsMessengerEXT>(
          vkGetInstanceProcAddr(instance_, "vkCreateDebugUtilsMessengerEXT"));
      if (!create) throw GpuError("Vulkan: vkCreateDebugUtilsMessengerEXT not available");
      vk_check(create(instance_, &dbg, nullptr, &messenger_), "vkCreateDebugUtilsMessengerEXT");
    }

    uint32_t n = 0;
    vk_check(vkEnumeratePhysicalDevices(instance_, &n, nullptr), "vkEnumeratePhysicalDevices");
    std::vector<VkPhysicalDevice> devs(n);
    if (n) vk_check(vkEnumeratePhysicalDevices(instance_, &n, devs.data()), "vkEnumeratePhysicalDevices");
    std::string want = device_name;
    if (want.empty())
      if (const char* e = std::getenv("SHADOWTILE_VK_DEVICE")) want = e;
    std::string names;
    std::vector<VkPhysicalDevice> match;
    for (VkPhysicalDevice d : devs) {
      VkPhysicalDeviceProperties p{};
      vkGetPhysicalDeviceProperties(d, &p);
      names += std::string(names.empty() ? "" : ", ") + "'" + p.deviceName + "'";
      if (want.empty() || std::strstr(p.deviceName, want.c_str())) match.push_back(d);
    }
    if (devs.empty()) throw GpuError("Vulkan: no Vulkan device on this machine (vkEnumeratePhysicalDevices found none)");
    if (match.empty()) throw GpuError("Vulkan: no device named like '" + want + "' (devices: " + names + ")");
    if (match.size() > 1)
      throw GpuError(std::string(want.empty() ? "Vulkan: several devices and none named" : "Vulkan: '" + want + "' names several devices") +
                     " (devices: " + names + "); choose one with GpuOptions::device or SHADOWTILE_VK_DEVICE");
    physical_ = match[0];
    vkGetPhysicalDeviceProperties(physical_, &props_);
    vkGetPhysicalDeviceMemoryProperties(physical_, &memory_);
    name_ = props_.deviceName;
    if (VK_API_VERSION_MINOR(props_.apiVersion) < 2 && VK_API_VERSION_MAJOR(props_.apiVersion) == 1)
      throw GpuError("Vulkan: device '" + name_ + "' supports only Vulkan 1." +
                     std::to_string(VK_API_VERSION_MINOR(props_.apiVersion)) + ", 1.2 is needed");

    uint32_t qn = 0;
    vkGetPhysicalDeviceQueueFamilyProperties(physical_, &qn, nullptr);
    std::vector<VkQueueFamilyProperties> qs(qn);
    vkGetPhysicalDeviceQueueFamilyProperties(physical_, &qn, qs.data());
    family_ = ~0u;
    for (uint32_t i = 0; i < qn && family_ == ~0u; ++i)
      if (qs[i].queueFlags & VK_QUEUE_COMPUTE_BIT) family_ = i;
    if (family_ == ~0u) throw GpuError("Vulkan: device '" + name_ + "' has no compute queue");
    timestamp_bits_ = props_.limits.timestampComputeAndGraphics ? qs[family_].timestampValidBits : 0;
    const float prio = 1.0f;
    VkDeviceQueueCreateInfo qci{};
    qci.sType = VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO;
    qci.queueFamilyIndex = family_;
    qci.queueCount = 1;
    qci.pQueuePriorities = &prio;
    VkDeviceCreateInfo dci{};
    dci.sType = VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO;
    dci.queueCreateInfoCount = 1;
    dci.pQueueCreateInfos = &qci;
    vk_check(vkCreateDevice(physical_, &dci, nullptr, &device_), "vkCreateDevice");
    vkGetDeviceQueue(device_, family_, 0, &queue_);
  } catch (...) {
    release();
    throw;
  }
}

VkContext::~VkContext() { release(); }

void VkContext::release() noexcept {
  if (device_) vkDestroyDevice(device_, nullptr);
  device_ = VK_NULL_HANDLE;
  if (messenger_) {
    auto destroy = reinterpret_cast<PFN_vkDestroyDebugUtilsMessengerEXT>(
        vkGetInstanceProcAddr(instance_, "vkDestroyDebugUtilsMessengerEXT"));
    if (destroy) destroy(instance_, messenger_, nullptr);
    messenger_ = VK_NULL_HANDLE;
  }
  if (instance_) vkDestroyInstance(instance_, nullptr);
  instance_ = VK_NULL_HANDLE;
}

uint32_t VkContext::memory_type(uint32_t bits, VkMemoryPropertyFlags want, VkMemoryPropertyFlags fallback) const {
  for (VkMemoryPropertyFlags f : {want, fallback})
    for (uint32_t i = 0; i < memory_.memoryTypeCount; ++i)
      if ((bits & (1u << i)) && (memory_.memoryTypes[i].propertyFlags & f) == f) return i;
  throw GpuError("Vulkan: device '" + name_ + "' has no suitable memory type");
}

VkBufferBox VkContext::make_buffer(VkDeviceSize size, bool host, VkBufferUsageFlags extra_usage) {
  VkBufferBox b;
  b.size = size;
  VkBufferCreateInfo bci{};
  bci.sType = VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO;
  bci.size = size;
  bci.usage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_SRC_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT |
              extra_usage;
  bci.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  vk_check(vkCreateBuffer(device_, &bci, nullptr, &b.buffer), "vkCreateBuffer");
  try {
    VkMemoryRequirements req{};
    vkGetBufferMemoryRequirements(device_, b.buffer, &req);
    const VkMemoryPropertyFlags hv = VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT;
    const uint32_t type = host ? memory_type(req.memoryTypeBits, hv | VK_MEMORY_PROPERTY_HOST_CACHED_BIT, hv)
                               : memory_type(req.memoryTypeBits, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT, 0);
    VkMemoryAllocateInfo mai{};
    mai.sType = VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO;
    mai.allocationSize = req.size;
    mai.memoryTypeIndex = type;
    vk_check(vkAllocateMemory(device_, &mai, nullptr, &b.memory), "vkAllocateMemory");
    vk_check(vkBindBufferMemory(device_, b.buffer, b.memory, 0), "vkBindBufferMemory");
    b.host_visible = host;
    if (host) vk_check(vkMapMemory(device_, b.memory, 0, VK_WHOLE_SIZE, 0, &b.mapped), "vkMapMemory");
  } catch (...) {
    destroy(b);
    throw;
  }
  return b;
}

VkCommandPool VkContext::make_command_pool(bool resettable_buffers) {
  VkCommandPoolCreateInfo cpi{};
  cpi.sType = VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO;
  cpi.flags = resettable_buffers ? VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT : 0;
  cpi.queueFamilyIndex = family_;
  VkCommandPool pool = VK_NULL_HANDLE;
  vk_check(vkCreateCommandPool(device_, &cpi, nullptr, &pool), "vkCreateCommandPool");
  return pool;
}

VkCommandBuffer VkContext::allocate_command_buffer(VkCommandPool pool) {
  VkCommandBufferAllocateInfo cai{};
  cai.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO;
  cai.commandPool = pool;
  cai.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
  cai.commandBufferCount = 1;
  VkCommandBuffer cmd = VK_NULL_HANDLE;
  vk_check(vkAllocateCommandBuffers(device_, &cai, &cmd), "vkAllocateCommandBuffers");
  return cmd;
}

VkFence VkContext::make_fence() {
  VkFenceCreateInfo fci{};
  fci.sType = VK_STRUCTURE_TYPE_FENCE_CREATE_INFO;
  VkFence fence = VK_NULL_HANDLE;
  vk_check(vkCreateFence(device_, &fci, nullptr, &fence), "vkCreateFence");
  return fence;
}

VkQueryPool VkContext::make_timestamp_queries(uint32_t count) {
  if (timestamp_bits_ == 0) return VK_NULL_HANDLE;
  VkQueryPoolCreateInfo qpi{};
  qpi.sType = VK_STRUCTURE_TYPE_QUERY_POOL_CREATE_INFO;
  qpi.queryType = VK_QUERY_TYPE_TIMESTAMP;
  qpi.queryCount = count;
  VkQueryPool queries = VK_NULL_HANDLE;
  vk_check(vkCreateQueryPool(device_, &qpi, nullptr, &queries), "vkCreateQueryPool");
  return queries;
}

void VkContext::destroy(VkBufferBox& b) {
  if (b.mapped) vkUnmapMemory(device_, b.memory);
  if (b.buffer) vkDestroyBuffer(device_, b.buffer, nullptr);
  if (b.memory) vkFreeMemory(device_, b.memory, nullptr);
  b = VkBufferBox{};
}

VkShaderModule VkContext::make_shader(std::span<const uint32_t> spirv) {
  VkShaderModuleCreateInfo sci{};
  sci.sType = VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO;
  sci.codeSize = spirv.size() * 4;
  sci.pCode = spirv.data();
  VkShaderModule m = VK_NULL_HANDLE;
  vk_check(vkCreateShaderModule(device_, &sci, nullptr, &m), "vkCreateShaderModule");
  return m;
}

}  // namespace st::gpu
