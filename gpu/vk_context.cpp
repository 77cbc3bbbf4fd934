#include "gpu/vk_context.hpp"

#include <cstdlib>
#include <cstring>

// gpu/ is compiled with VK_NO_PROTOTYPES: the one symbol taken from the loader we link
// (the own-device mode's only way in; engine mode uses the engine's).
extern "C" VKAPI_ATTR PFN_vkVoidFunction VKAPI_CALL vkGetInstanceProcAddr(VkInstance instance, const char* name);

namespace st::gpu {

void VkFunctions::load_instance(PFN_vkGetInstanceProcAddr gipa, VkInstance instance) {
#define ST_VK_LOAD(name)                                                                        \
  name = reinterpret_cast<PFN_vk##name>(gipa(instance, "vk" #name));                            \
  if (!name) throw GpuError("Vulkan: vkGetInstanceProcAddr returned no vk" #name);
  ST_VK_INSTANCE_FUNCTIONS(ST_VK_LOAD)
#undef ST_VK_LOAD
}

void VkFunctions::load_device(PFN_vkGetDeviceProcAddr gdpa, VkDevice device) {
  if (!gdpa) gdpa = GetDeviceProcAddr;
#define ST_VK_LOAD(name)                                                                        \
  name = reinterpret_cast<PFN_vk##name>(gdpa(device, "vk" #name));                              \
  if (!name) throw GpuError("Vulkan: vkGetDeviceProcAddr returned no vk" #name);
  ST_VK_DEVICE_FUNCTIONS(ST_VK_LOAD)
#undef ST_VK_LOAD
}

// The default GpuAllocator: one vkAllocateMemory per buffer (GpuMap makes a handful, once).
class VkContext::DefaultAllocator final : public GpuAllocator {
 public:
  explicit DefaultAllocator(const VkContext& c) : c_(c) {}
  VkResult create_buffer(const VkBufferCreateInfo& info, BufferUse use, GpuBuffer& out) override {
    static_assert(sizeof(void*) >= sizeof(VkDeviceMemory), "GpuBuffer::allocation holds a VkDeviceMemory");
    const VkMemoryPropertyFlags hv = VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT;
    const VkMemoryPropertyFlags want = use == BufferUse::device_local ? VkMemoryPropertyFlags(VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT)
                                       : use == BufferUse::readback   ? hv | VK_MEMORY_PROPERTY_HOST_CACHED_BIT
                                                                      : hv;
    const VkMemoryPropertyFlags fallback = use == BufferUse::device_local ? 0 : hv;
    vk_setup::Buffer b;
    out = GpuBuffer{};
    const VkResult r =
        vk_setup::create_buffer(c_.setup(), c_.memory_, info, want, fallback, use != BufferUse::device_local, b);
    if (r != VK_SUCCESS) return r;
    out.buffer = b.buffer;
    out.allocation = reinterpret_cast<void*>(b.memory);
    out.mapped = b.mapped;
    out.size = info.size;
    return VK_SUCCESS;
  }
  void destroy_buffer(GpuBuffer& b) noexcept override {
    vk_setup::Buffer own{b.buffer, reinterpret_cast<VkDeviceMemory>(b.allocation), b.mapped};
    vk_setup::destroy(c_.setup(), own);
    b = GpuBuffer{};
  }

 private:
  const VkContext& c_;
};

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
    const PFN_vkGetInstanceProcAddr gipa = &::vkGetInstanceProcAddr;
    const auto EnumerateInstanceLayerProperties = reinterpret_cast<PFN_vkEnumerateInstanceLayerProperties>(
        gipa(VK_NULL_HANDLE, "vkEnumerateInstanceLayerProperties"));
    const auto CreateInstance = reinterpret_cast<PFN_vkCreateInstance>(gipa(VK_NULL_HANDLE, "vkCreateInstance"));
    if (!EnumerateInstanceLayerProperties || !CreateInstance) throw GpuError("Vulkan: the loader returned no vkCreateInstance");
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
      vk_check(EnumerateInstanceLayerProperties(&n, nullptr), "vkEnumerateInstanceLayerProperties");
      std::vector<VkLayerProperties> have(n);
      vk_check(EnumerateInstanceLayerProperties(&n, have.data()), "vkEnumerateInstanceLayerProperties");
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
    const VkResult ir = CreateInstance(&ici, nullptr, &instance_);
    if (ir == VK_ERROR_INCOMPATIBLE_DRIVER || ir == VK_ERROR_INITIALIZATION_FAILED)
      throw GpuError(std::string("Vulkan: no Vulkan driver found (vkCreateInstance: ") + vk_result_name(ir) +
                     "); install one, e.g. mesa-vulkan-drivers for lavapipe");
    vk_check(ir, "vkCreateInstance");
    vk.load_instance(gipa, instance_);
    if (validation) {
      auto create = reinterpret_cast<PFN_vkCreateDebugUtilsMessengerEXT>(
          gipa(instance_, "vkCreateDebugUtilsMessengerEXT"));
      if (!create) throw GpuError("Vulkan: vkCreateDebugUtilsMessengerEXT not available");
      vk_check(create(instance_, &dbg, nullptr, &messenger_), "vkCreateDebugUtilsMessengerEXT");
    }

    uint32_t n = 0;
    vk_check(vk.EnumeratePhysicalDevices(instance_, &n, nullptr), "vkEnumeratePhysicalDevices");
    std::vector<VkPhysicalDevice> devs(n);
    if (n) vk_check(vk.EnumeratePhysicalDevices(instance_, &n, devs.data()), "vkEnumeratePhysicalDevices");
    std::string want = device_name;
    if (want.empty())
      if (const char* e = std::getenv("SHADOWTILE_VK_DEVICE")) want = e;
    std::string names;
    std::vector<VkPhysicalDevice> match;
    for (VkPhysicalDevice d : devs) {
      VkPhysicalDeviceProperties p{};
      vk.GetPhysicalDeviceProperties(d, &p);
      names += std::string(names.empty() ? "" : ", ") + "'" + p.deviceName + "'";
      if (want.empty() || std::strstr(p.deviceName, want.c_str())) match.push_back(d);
    }
    if (devs.empty()) throw GpuError("Vulkan: no Vulkan device on this machine (vkEnumeratePhysicalDevices found none)");
    if (match.empty()) throw GpuError("Vulkan: no device named like '" + want + "' (devices: " + names + ")");
    if (match.size() > 1)
      throw GpuError(std::string(want.empty() ? "Vulkan: several devices and none named" : "Vulkan: '" + want + "' names several devices") +
                     " (devices: " + names + "); choose one with GpuOptions::device or SHADOWTILE_VK_DEVICE");
    physical_ = match[0];
    read_device_properties();

    uint32_t qn = 0;
    vk.GetPhysicalDeviceQueueFamilyProperties(physical_, &qn, nullptr);
    std::vector<VkQueueFamilyProperties> qs(qn);
    vk.GetPhysicalDeviceQueueFamilyProperties(physical_, &qn, qs.data());
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
    vk_check(vk.CreateDevice(physical_, &dci, nullptr, &device_), "vkCreateDevice");
    vk.load_device(nullptr, device_);
    vk.GetDeviceQueue(device_, family_, 0, &queue_);
    own_allocator_ = std::make_unique<DefaultAllocator>(*this);
    allocator_ = own_allocator_.get();
  } catch (...) {
    release();
    throw;
  }
}

VkContext::VkContext(const EngineDevice& e) : borrowed_(true) {
  if (!e.instance || !e.physical_device || !e.device || !e.get_instance_proc_addr)
    throw GpuError("GpuMap: EngineDevice needs instance, physical_device, device and get_instance_proc_addr");
  instance_ = e.instance;
  physical_ = e.physical_device;
  device_ = e.device;
  family_ = e.queue_family;
  callbacks_ = e.allocation_callbacks;
  vk.load_instance(e.get_instance_proc_addr, instance_);
  vk.load_device(e.get_device_proc_addr, device_);
  read_device_properties();
  uint32_t qn = 0;
  vk.GetPhysicalDeviceQueueFamilyProperties(physical_, &qn, nullptr);
  std::vector<VkQueueFamilyProperties> qs(qn);
  vk.GetPhysicalDeviceQueueFamilyProperties(physical_, &qn, qs.data());
  if (family_ >= qn || !(qs[family_].queueFlags & VK_QUEUE_COMPUTE_BIT))
    throw GpuError("GpuMap: EngineDevice::queue_family " + std::to_string(family_) + " of '" + name_ +
                   "' is not a family with compute (the shadow pass and uploads are recorded for it)");
  if (e.allocator) {
    allocator_ = e.allocator;
  } else {
    own_allocator_ = std::make_unique<DefaultAllocator>(*this);
    allocator_ = own_allocator_.get();
  }
}

void VkContext::read_device_properties() {
  vk.GetPhysicalDeviceProperties(physical_, &props_);
  vk.GetPhysicalDeviceMemoryProperties(physical_, &memory_);
  name_ = props_.deviceName;
  if (VK_API_VERSION_MINOR(props_.apiVersion) < 2 && VK_API_VERSION_MAJOR(props_.apiVersion) == 1)
    throw GpuError("Vulkan: device '" + name_ + "' supports only Vulkan 1." +
                   std::to_string(VK_API_VERSION_MINOR(props_.apiVersion)) + ", 1.2 is needed");
}

VkContext::~VkContext() { release(); }

void VkContext::release() noexcept {
  own_allocator_.reset();
  allocator_ = nullptr;
  if (borrowed_) return;  // the engine's objects: never ours to destroy
  if (device_ && vk.DestroyDevice) vk.DestroyDevice(device_, nullptr);
  device_ = VK_NULL_HANDLE;
  if (messenger_) {
    auto destroy = reinterpret_cast<PFN_vkDestroyDebugUtilsMessengerEXT>(
        ::vkGetInstanceProcAddr(instance_, "vkDestroyDebugUtilsMessengerEXT"));
    if (destroy) destroy(instance_, messenger_, nullptr);
    messenger_ = VK_NULL_HANDLE;
  }
  if (instance_ && vk.DestroyInstance) vk.DestroyInstance(instance_, nullptr);
  instance_ = VK_NULL_HANDLE;
}

VkBufferBox VkContext::make_buffer(VkDeviceSize size, bool host, VkBufferUsageFlags extra_usage, BufferUse host_use) {
  VkBufferCreateInfo bci{};
  bci.sType = VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO;
  bci.size = size;
  bci.usage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_SRC_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT |
              extra_usage;
  bci.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  const BufferUse use = host ? (host_use == BufferUse::upload ? BufferUse::upload : BufferUse::readback) : BufferUse::device_local;
  VkBufferBox b;
  const VkResult r = allocator_->create_buffer(bci, use, b);
  if (r != VK_SUCCESS)
    throw GpuError("Vulkan: creating a buffer of " + std::to_string(size) + " bytes on '" + name_ + "' failed: " +
                   vk_result_name(r));
  if (host && !b.mapped) {
    allocator_->destroy_buffer(b);
    throw GpuError("GpuMap: the allocator returned a host-visible buffer that is not mapped");
  }
  b.size = size;
  return b;
}

VkCommandPool VkContext::make_command_pool(bool resettable_buffers) {
  return vk_setup::command_pool(setup(), family_, resettable_buffers);
}

VkCommandBuffer VkContext::allocate_command_buffer(VkCommandPool pool) {
  VkCommandBuffer cmd = VK_NULL_HANDLE;
  vk_setup::command_buffers(setup(), pool, {&cmd, 1});
  return cmd;
}

VkFence VkContext::make_fence() { return vk_setup::fence(setup(), false); }

VkQueryPool VkContext::make_timestamp_queries(uint32_t count) {
  if (timestamp_bits_ == 0) return VK_NULL_HANDLE;
  return vk_setup::timestamp_queries(setup(), count);
}

void VkContext::destroy(VkBufferBox& b) {
  if (b.buffer && allocator_) allocator_->destroy_buffer(b);
  b = VkBufferBox{};
}

VkShaderModule VkContext::make_shader(std::span<const uint32_t> spirv) { return vk_setup::shader_module(setup(), spirv); }

}  // namespace st::gpu
