// engine_device.hpp: an engine's own Vulkan device, created the way a renderer creates it
// (the plain loader, no shadowtile code): instance, physical device chosen by name, one
// queue, the logical device. GpuMap borrows it through gpu::EngineDevice (engine mode).
// The rasterizer of raster.hpp and bench_frame_path (bench/frame_path.cpp) both stand on
// it; command pools, buffers, pipelines and fences stay with whoever records.
// Errors: std::runtime_error naming what failed (no device of that name lists the present ones).
#pragma once
#include <vulkan/vulkan.h>

#include <cstdint>
#include <string>

#include "shadowtile/gpu.hpp"

namespace st::raster {

struct EngineDeviceOptions {
  std::string device;  // a substring of the device's name; empty: SHADOWTILE_VK_DEVICE, else the first
  // VK_LAYER_KHRONOS_validation with a messenger counting its warnings and errors (messages(),
  // first_message()); runtime_error when the layer is absent.
  bool validation = false;
  // true: a graphics + compute queue and fragmentStoresAndAtomics (a fragment shader writes
  // GpuMap's feedback: the rasterizer). false: the first queue with compute and no features
  // (a frame path that records only GpuMap's copies and compute).
  bool graphics = true;
  std::string app_name = "shadowtile raster";
};

class VulkanDevice {
 public:
  explicit VulkanDevice(const EngineDeviceOptions& options);
  ~VulkanDevice();  // destroys the device and instance (the owner waits for its work first)
  VulkanDevice(const VulkanDevice&) = delete;
  VulkanDevice& operator=(const VulkanDevice&) = delete;

  // What GpuMap borrows.
  gpu::EngineDevice engine_device() const;

  uint64_t messages() const { return messages_; }  // validation: warnings and errors so far
  const std::string& first_message() const { return first_message_; }

  VkInstance instance = VK_NULL_HANDLE;
  VkPhysicalDevice physical = VK_NULL_HANDLE;
  VkDevice device = VK_NULL_HANDLE;
  VkQueue queue = VK_NULL_HANDLE;
  uint32_t family = ~0u;
  VkPhysicalDeviceMemoryProperties mem{};
  VkPhysicalDeviceProperties props{};
  uint32_t timestamp_bits = 0;  // the queue's valid timestamp bits (0: no timestamps)
  std::string name;

 private:
  static VKAPI_ATTR VkBool32 VKAPI_CALL on_message(VkDebugUtilsMessageSeverityFlagBitsEXT,
                                                   VkDebugUtilsMessageTypeFlagsEXT,
                                                   const VkDebugUtilsMessengerCallbackDataEXT* data, void* user);
  void destroy_instance();
  VkDebugUtilsMessengerEXT messenger_ = VK_NULL_HANDLE;
  uint64_t messages_ = 0;
  std::string first_message_;
};

}  // namespace st::raster
