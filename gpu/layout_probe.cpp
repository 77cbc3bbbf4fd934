#include "gpu/layout_probe.hpp"

#include <cstring>

#include "gpu/kernels.hpp"

namespace st::gpu {

std::vector<uint32_t> run_layout_probe(const std::string& device, bool validation, uint64_t* validation_messages) {
  VkContext ctx(device, validation);
  Kernels kernels;
  std::vector<VkBufferBox> bufs;
  VkCommandPool pool = VK_NULL_HANDLE;
  VkFence fence = VK_NULL_HANDLE;
  std::vector<uint32_t> out(layout::kProbeWords, 0);
  auto cleanup = [&] {
    vkDeviceWaitIdle(ctx.device());
    if (fence) vkDestroyFence(ctx.device(), fence, nullptr);
    if (pool) vkDestroyCommandPool(ctx.device(), pool, nullptr);
    for (VkBufferBox& b : bufs) ctx.destroy(b);
    kernels.destroy(ctx);
  };
  try {
    kernels.create(ctx, 1);
    for (int i = 0; i < 6; ++i) bufs.push_back(ctx.make_buffer(layout::kProbeWords * 4, true));
    const VkDescriptorSet set = kernels.bind(ctx, 0, {bufs[0].buffer, bufs[1].buffer, bufs[2].buffer, bufs[3].buffer,
                                                      bufs[4].buffer, bufs[5].buffer});
    pool = ctx.make_command_pool(false);
    VkCommandBuffer cmd = ctx.allocate_command_buffer(pool);
    VkCommandBufferBeginInfo bi{};
    bi.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO;
    vk_check(vkBeginCommandBuffer(cmd, &bi), "vkBeginCommandBuffer");
    const uint32_t pc[layout::kPcWords] = {};
    kernels.record(cmd, Kernel::layout_probe, set, pc);
    vkCmdDispatch(cmd, 1, 1, 1);
    VkMemoryBarrier host{};
    host.sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER;
    host.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT;
    host.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
    vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_PIPELINE_STAGE_HOST_BIT, 0, 1, &host, 0, nullptr, 0,
                         nullptr);
    vk_check(vkEndCommandBuffer(cmd), "vkEndCommandBuffer");
    fence = ctx.make_fence();
    VkSubmitInfo si{};
    si.sType = VK_STRUCTURE_TYPE_SUBMIT_INFO;
    si.commandBufferCount = 1;
    si.pCommandBuffers = &cmd;
    vk_check(vkQueueSubmit(ctx.queue(), 1, &si, fence), "vkQueueSubmit");
    vk_check(vkWaitForFences(ctx.device(), 1, &fence, VK_TRUE, UINT64_MAX), "vkWaitForFences");
    std::memcpy(out.data(), bufs[4].mapped, out.size() * 4);
  } catch (...) {
    cleanup();
    throw;
  }
  cleanup();
  if (validation_messages) *validation_messages = ctx.validation_messages();
  return out;
}

}  // namespace st::gpu
