// Every Vulkan entry point gpu/ calls, loaded at run time from vkGetInstanceProcAddr and
// vkGetDeviceProcAddr: the engine's own (EngineDevice) or, for the own-device mode, the
// loader's. gpu/ is compiled with VK_NO_PROTOTYPES, so a direct vkFoo() call does not
// compile: every call goes through a VkFunctions table. Internal to gpu/.
#pragma once
#include <vulkan/vulkan.h>

namespace st::gpu {

// Instance-level functions (loaded with the instance).
#define ST_VK_INSTANCE_FUNCTIONS(X)          \
  X(DestroyInstance)                         \
  X(EnumeratePhysicalDevices)                \
  X(GetPhysicalDeviceProperties)             \
  X(GetPhysicalDeviceMemoryProperties)       \
  X(GetPhysicalDeviceQueueFamilyProperties)  \
  X(GetPhysicalDeviceFeatures)               \
  X(CreateDevice)                            \
  X(GetDeviceProcAddr)

// Device-level functions (loaded with the device through vkGetDeviceProcAddr).
#define ST_VK_DEVICE_FUNCTIONS(X) \
  X(DestroyDevice)                \
  X(GetDeviceQueue)               \
  X(DeviceWaitIdle)               \
  X(QueueSubmit)                  \
  X(CreateBuffer)                 \
  X(DestroyBuffer)                \
  X(CreateBufferView)             \
  X(DestroyBufferView)            \
  X(GetBufferMemoryRequirements)  \
  X(AllocateMemory)               \
  X(FreeMemory)                   \
  X(BindBufferMemory)             \
  X(MapMemory)                    \
  X(UnmapMemory)                  \
  X(CreateShaderModule)           \
  X(DestroyShaderModule)          \
  X(CreateDescriptorSetLayout)    \
  X(DestroyDescriptorSetLayout)   \
  X(CreatePipelineLayout)         \
  X(DestroyPipelineLayout)        \
  X(CreateComputePipelines)       \
  X(DestroyPipeline)              \
  X(CreateDescriptorPool)         \
  X(DestroyDescriptorPool)        \
  X(AllocateDescriptorSets)       \
  X(UpdateDescriptorSets)         \
  X(CreateSampler)                \
  X(DestroySampler)               \
  X(CreateCommandPool)            \
  X(DestroyCommandPool)           \
  X(AllocateCommandBuffers)       \
  X(ResetCommandBuffer)           \
  X(BeginCommandBuffer)           \
  X(EndCommandBuffer)             \
  X(CreateFence)                  \
  X(DestroyFence)                 \
  X(WaitForFences)                \
  X(ResetFences)                  \
  X(CreateQueryPool)              \
  X(DestroyQueryPool)             \
  X(GetQueryPoolResults)          \
  X(CmdPipelineBarrier)           \
  X(CmdCopyBuffer)                \
  X(CmdFillBuffer)                \
  X(CmdUpdateBuffer)              \
  X(CmdBindPipeline)              \
  X(CmdBindDescriptorSets)        \
  X(CmdPushConstants)             \
  X(CmdDispatch)                  \
  X(CmdResetQueryPool)            \
  X(CmdWriteTimestamp)

struct VkFunctions {
#define ST_VK_MEMBER(name) PFN_vk##name name = nullptr;
  ST_VK_INSTANCE_FUNCTIONS(ST_VK_MEMBER)
  ST_VK_DEVICE_FUNCTIONS(ST_VK_MEMBER)
#undef ST_VK_MEMBER

  // Loads the instance-level table from `gipa` (throws GpuError naming a missing one).
  void load_instance(PFN_vkGetInstanceProcAddr gipa, VkInstance instance);
  // Loads the device-level table from `gdpa` (or, when null, the instance's
  // vkGetDeviceProcAddr loaded above).
  void load_device(PFN_vkGetDeviceProcAddr gdpa, VkDevice device);
};

}  // namespace st::gpu
