// The engine's Vulkan device of engine_device.hpp.
#include "examples/raster/engine_device.hpp"

#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <vector>

namespace st::raster {

VKAPI_ATTR VkBool32 VKAPI_CALL VulkanDevice::on_message(VkDebugUtilsMessageSeverityFlagBitsEXT,
                                                        VkDebugUtilsMessageTypeFlagsEXT,
                                                        const VkDebugUtilsMessengerCallbackDataEXT* data, void* user) {
  auto* d = static_cast<VulkanDevice*>(user);
  if (d->messages_++ == 0 && data && data->pMessage) d->first_message_ = data->pMessage;
  return VK_FALSE;
}

VulkanDevice::VulkanDevice(const EngineDeviceOptions& o) {
  std::string want = o.device;
  if (want.empty())
    if (const char* e = std::getenv("SHADOWTILE_VK_DEVICE")) want = e;
  VkApplicationInfo app{};
  app.sType = VK_STRUCTURE_TYPE_APPLICATION_INFO;
  app.pApplicationName = o.app_name.empty() ? nullptr : o.app_name.c_str();
  app.apiVersion = VK_API_VERSION_1_2;
  VkInstanceCreateInfo ici{};
  ici.sType = VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO;
  ici.pApplicationInfo = &app;
  const char* layer = "VK_LAYER_KHRONOS_validation";
  const char* ext = VK_EXT_DEBUG_UTILS_EXTENSION_NAME;
  VkDebugUtilsMessengerCreateInfoEXT mci{};
  mci.sType = VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT;
  mci.messageSeverity = VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT;
  mci.messageType = VK_DEBUG_UTILS_MESSAGE_TYPE_GENERAL_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT;
  mci.pfnUserCallback = &on_message;
  mci.pUserData = this;
  if (o.validation) {
    ici.enabledLayerCount = 1;
    ici.ppEnabledLayerNames = &layer;
    ici.enabledExtensionCount = 1;
    ici.ppEnabledExtensionNames = &ext;
    ici.pNext = &mci;  // instance creation and destruction too
  }
  if (VkResult r = vkCreateInstance(&ici, nullptr, &instance); r != VK_SUCCESS)
    throw std::runtime_error(std::string("vkCreateInstance failed: VkResult ") + std::to_string(int(r)) +
                             (o.validation ? " (is VK_LAYER_KHRONOS_validation installed?)" : ""));
  // From here a failure destroys what was created before it throws.
  auto fail = [&](const std::string& what) {
    destroy_instance();
    throw std::runtime_error(what);
  };
  if (o.validation) {
    auto create = reinterpret_cast<PFN_vkCreateDebugUtilsMessengerEXT>(
        vkGetInstanceProcAddr(instance, "vkCreateDebugUtilsMessengerEXT"));
    if (!create || create(instance, &mci, nullptr, &messenger_) != VK_SUCCESS) {
      messenger_ = VK_NULL_HANDLE;
      fail("vkCreateDebugUtilsMessengerEXT failed");
    }
  }
  uint32_t n = 0;
  vkEnumeratePhysicalDevices(instance, &n, nullptr);
  std::vector<VkPhysicalDevice> devs(n);
  vkEnumeratePhysicalDevices(instance, &n, devs.data());
  std::string names;
  for (VkPhysicalDevice d : devs) {
    VkPhysicalDeviceProperties p{};
    vkGetPhysicalDeviceProperties(d, &p);
    names += std::string(names.empty() ? "" : ", ") + "'" + p.deviceName + "'";
    if (!physical && (want.empty() || std::strstr(p.deviceName, want.c_str()))) physical = d, props = p;
  }
  if (!physical) fail("no Vulkan device named like '" + want + "' (present: " + (names.empty() ? "none" : names) + ")");
  name = props.deviceName;
  vkGetPhysicalDeviceMemoryProperties(physical, &mem);
  uint32_t qn = 0;
  vkGetPhysicalDeviceQueueFamilyProperties(physical, &qn, nullptr);
  std::vector<VkQueueFamilyProperties> qs(qn);
  vkGetPhysicalDeviceQueueFamilyProperties(physical, &qn, qs.data());
  const VkQueueFlags need = o.graphics ? VK_QUEUE_GRAPHICS_BIT | VK_QUEUE_COMPUTE_BIT : VK_QUEUE_COMPUTE_BIT;
  for (uint32_t i = 0; i < qn && family == ~0u; ++i)
    if ((qs[i].queueFlags & need) == need) family = i;
  if (family == ~0u) fail("device '" + name + "' has no " + (o.graphics ? "graphics + compute" : "compute") + " queue");
  timestamp_bits = props.limits.timestampComputeAndGraphics ? qs[family].timestampValidBits : 0;
  VkPhysicalDeviceFeatures features{};
  if (o.graphics) {
    VkPhysicalDeviceFeatures have{};
    vkGetPhysicalDeviceFeatures(physical, &have);
    if (!have.fragmentStoresAndAtomics)
      fail("device '" + name + "' has no fragmentStoresAndAtomics (the fragment shader writes feedback)");
    features.fragmentStoresAndAtomics = VK_TRUE;
  }
  const float prio = 1;
  VkDeviceQueueCreateInfo qci{};
  qci.sType = VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO;
  qci.queueFamilyIndex = family;
  qci.queueCount = 1;
  qci.pQueuePriorities = &prio;
  VkDeviceCreateInfo dci{};
  dci.sType = VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO;
  dci.queueCreateInfoCount = 1;
  dci.pQueueCreateInfos = &qci;
  dci.pEnabledFeatures = o.graphics ? &features : nullptr;
  if (VkResult r = vkCreateDevice(physical, &dci, nullptr, &device); r != VK_SUCCESS) {
    device = VK_NULL_HANDLE;
    fail("vkCreateDevice failed: VkResult " + std::to_string(int(r)));
  }
  vkGetDeviceQueue(device, family, 0, &queue);
}

VulkanDevice::~VulkanDevice() {
  if (device) vkDestroyDevice(device, nullptr);
  destroy_instance();
}

void VulkanDevice::destroy_instance() {
  if (messenger_) {
    auto destroy = reinterpret_cast<PFN_vkDestroyDebugUtilsMessengerEXT>(
        vkGetInstanceProcAddr(instance, "vkDestroyDebugUtilsMessengerEXT"));
    if (destroy) destroy(instance, messenger_, nullptr);
    messenger_ = VK_NULL_HANDLE;
  }
  if (instance) vkDestroyInstance(instance, nullptr);
  instance = VK_NULL_HANDLE;
}

gpu::EngineDevice VulkanDevice::engine_device() const {
  gpu::EngineDevice d;
  d.instance = instance;
  d.physical_device = physical;
  d.device = device;
  d.queue_family = family;
  d.get_instance_proc_addr = &vkGetInstanceProcAddr;
  d.get_device_proc_addr = &vkGetDeviceProcAddr;
  return d;
}

}  // namespace st::raster
