// The Vulkan 1.2 context behind GpuMap, in one of two modes. Own device: instance
// (optionally with the Khronos validation layer and a debug messenger that counts every
// error and warning), the one physical device chosen by name, one compute queue. Engine:
// the engine's instance, device and queue family borrowed (EngineDevice), nothing created
// or destroyed but our own objects. Either way every call goes through `vk`, the table
// loaded from the loaders (vk_functions.hpp), and buffers through a GpuAllocator (the
// engine's, or the default one here). Internal to gpu/.
//
// Device choice, never by chance: the name asked for (GpuOptions::device, else the
// environment variable SHADOWTILE_VK_DEVICE) must be a substring of exactly one device's
// name; with no name asked for, the machine must have exactly one device. Anything else is
// a GpuError listing the devices there are.
//
// Errors: every failing Vulkan call becomes a GpuError naming the call and its VkResult.
#pragma once
#include <vulkan/vulkan.h>

#include <atomic>
#include <memory>
#include <cstdint>
#include <mutex>
#include <span>
#include <string>
#include <vector>

#include "gpu/gpu_map.hpp"
#include "gpu/vk_functions.hpp"
#include "shadowtile/vk_setup.hpp"

namespace st::gpu {

// Throws GpuError("Vulkan: <call> failed: <VkResult>") unless r is VK_SUCCESS.
void vk_check(VkResult r, const char* call);
const char* vk_result_name(VkResult r);

// A buffer from the context's allocator (host-visible ones stay mapped).
using VkBufferBox = GpuBuffer;

class VkContext {
 public:
  VkContext(const std::string& device_name, bool validation);
  explicit VkContext(const EngineDevice& engine);  // borrows; throws GpuError on a bad EngineDevice
  ~VkContext();
  VkContext(const VkContext&) = delete;
  VkContext& operator=(const VkContext&) = delete;

  VkFunctions vk;  // every Vulkan call of gpu/ goes through this table
  // The device for <shadowtile/vk_setup.hpp>: this table, our callbacks, GpuError on failure.
  vk_setup::Device<VkFunctions> setup() const { return {vk, device_, callbacks_, &vk_check}; }

  bool borrowed() const { return borrowed_; }  // engine mode
  const VkAllocationCallbacks* callbacks() const { return callbacks_; }
  VkDevice device() const { return device_; }
  VkPhysicalDevice physical() const { return physical_; }
  VkQueue queue() const { return queue_; }  // VK_NULL_HANDLE in engine mode: we never submit
  uint32_t queue_family() const { return family_; }
  const std::string& device_name() const { return name_; }
  const VkPhysicalDeviceProperties& properties() const { return props_; }
  uint32_t timestamp_bits() const { return timestamp_bits_; }  // 0: no timestamps on the queue

  // Storage buffer. `host`: host-visible and coherent, mapped (staging, readback, small
  // inputs); else device-local where the device has such memory (the pool, the page table).
  // `host`: BufferUse::readback unless `use` says upload.
  VkBufferBox make_buffer(VkDeviceSize size, bool host, VkBufferUsageFlags extra_usage = 0,
                          BufferUse host_use = BufferUse::readback);
  void destroy(VkBufferBox& b);

  VkShaderModule make_shader(std::span<const uint32_t> spirv);

  // Command and sync objects on the one queue family. The caller destroys them with the
  // matching vkDestroy* call (the pool frees its command buffers).
  VkCommandPool make_command_pool(bool resettable_buffers);
  VkCommandBuffer allocate_command_buffer(VkCommandPool pool);
  VkFence make_fence();
  // `count` timestamp queries, or VK_NULL_HANDLE when the queue has no timestamps.
  VkQueryPool make_timestamp_queries(uint32_t count);

  // Validation messages seen (errors and warnings) and the first one's text.
  uint64_t validation_messages() const { return messages_.load(); }
  std::string first_validation_message() const;

 private:
  static VKAPI_ATTR VkBool32 VKAPI_CALL on_message(VkDebugUtilsMessageSeverityFlagBitsEXT severity,
                                                   VkDebugUtilsMessageTypeFlagsEXT types,
                                                   const VkDebugUtilsMessengerCallbackDataEXT* data, void* self);
  void release() noexcept;
  void read_device_properties();

 private:
  class DefaultAllocator;
  std::unique_ptr<GpuAllocator> own_allocator_;
  GpuAllocator* allocator_ = nullptr;
  const VkAllocationCallbacks* callbacks_ = nullptr;
  bool borrowed_ = false;

  VkInstance instance_ = VK_NULL_HANDLE;
  VkDebugUtilsMessengerEXT messenger_ = VK_NULL_HANDLE;
  VkPhysicalDevice physical_ = VK_NULL_HANDLE;
  VkDevice device_ = VK_NULL_HANDLE;
  VkQueue queue_ = VK_NULL_HANDLE;
  uint32_t family_ = 0, timestamp_bits_ = 0;
  std::string name_;
  VkPhysicalDeviceProperties props_{};
  VkPhysicalDeviceMemoryProperties memory_{};
  std::atomic<uint64_t> messages_{0};
  mutable std::mutex message_mu_;
  std::string first_message_;
};

}  // namespace st::gpu
