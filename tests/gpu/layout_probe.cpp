#include "tests/gpu/layout_probe.hpp"

#include <algorithm>
#include <cstring>

#include "gpu/kernels.hpp"

namespace st::gpu {

namespace {

const uint32_t kLayoutProbeSpv[] = {
#include "tests/gpu/layout_probe.comp.spv.inc"
};
const std::span<const uint32_t> kLayoutProbeKernel[] = {kLayoutProbeSpv};

// One dispatch of layout_probe.comp: `input` in binding 2, push-constant count `count`,
// returns `out_words` words of binding 4.
std::vector<uint32_t> run_probe(const std::string& device, bool validation, std::span<const uint32_t> input,
                                uint32_t count, size_t out_words, uint64_t* validation_messages) {
  VkContext ctx(device, validation);
  Kernels kernels;
  std::vector<VkBufferBox> bufs;
  VkCommandPool pool = VK_NULL_HANDLE;
  VkFence fence = VK_NULL_HANDLE;
  std::vector<uint32_t> out(out_words, 0);
  const size_t words = std::max({size_t(layout::kProbeWords), input.size(), out_words});
  auto cleanup = [&] {
    ctx.vk.DeviceWaitIdle(ctx.device());
    if (fence) ctx.vk.DestroyFence(ctx.device(), fence, nullptr);
    if (pool) ctx.vk.DestroyCommandPool(ctx.device(), pool, nullptr);
    for (VkBufferBox& b : bufs) ctx.destroy(b);
    kernels.destroy(ctx);
  };
  try {
    kernels.create(ctx, 1, {}, kLayoutProbeKernel);
    for (int i = 0; i < 6; ++i) bufs.push_back(ctx.make_buffer(words * 4, true));
    std::memset(bufs[2].mapped, 0, words * 4);
    if (!input.empty()) std::memcpy(bufs[2].mapped, input.data(), input.size() * 4);
    const VkDescriptorSet set = kernels.bind(ctx, 0, {bufs[0].buffer, bufs[1].buffer, bufs[2].buffer, bufs[3].buffer,
                                                      bufs[4].buffer, bufs[5].buffer});
    pool = ctx.make_command_pool(false);
    VkCommandBuffer cmd = ctx.allocate_command_buffer(pool);
    VkCommandBufferBeginInfo bi{};
    bi.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO;
    vk_check(ctx.vk.BeginCommandBuffer(cmd, &bi), "vkBeginCommandBuffer");
    uint32_t pc[layout::kPcWords] = {};
    pc[layout::kPcCount] = count;
    kernels.record(cmd, extra_kernel(0), set, pc);
    ctx.vk.CmdDispatch(cmd, std::max(1u, (count + layout::kWorkgroupSize - 1) / layout::kWorkgroupSize), 1, 1);
    VkMemoryBarrier host{};
    host.sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER;
    host.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT;
    host.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
    ctx.vk.CmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_PIPELINE_STAGE_HOST_BIT, 0, 1, &host, 0, nullptr, 0,
                         nullptr);
    vk_check(ctx.vk.EndCommandBuffer(cmd), "vkEndCommandBuffer");
    fence = ctx.make_fence();
    VkSubmitInfo si{};
    si.sType = VK_STRUCTURE_TYPE_SUBMIT_INFO;
    si.commandBufferCount = 1;
    si.pCommandBuffers = &cmd;
    vk_check(ctx.vk.QueueSubmit(ctx.queue(), 1, &si, fence), "vkQueueSubmit");
    vk_check(ctx.vk.WaitForFences(ctx.device(), 1, &fence, VK_TRUE, UINT64_MAX), "vkWaitForFences");
    std::memcpy(out.data(), bufs[4].mapped, out.size() * 4);
  } catch (...) {
    cleanup();
    throw;
  }
  cleanup();
  if (validation_messages) *validation_messages = ctx.validation_messages();
  return out;
}

}  // namespace

std::vector<uint32_t> run_layout_probe(const std::string& device, bool validation, uint64_t* validation_messages) {
  return run_probe(device, validation, {}, 0, layout::kProbeWords, validation_messages);
}

std::vector<uint32_t> run_fdiv_probe(const std::string& device, bool validation, std::span<const uint32_t> a,
                                     std::span<const uint32_t> b, std::span<const int32_t> skew,
                                     uint64_t* validation_messages) {
  if (a.size() != b.size() || a.empty() || a.size() > (size_t(1) << 22) || (!skew.empty() && skew.size() != a.size()))
    throw GpuError("run_fdiv_probe: want 1..2^22 pairs of equal counts (and no skews or one per pair)");
  std::vector<uint32_t> input(3 * a.size());
  for (size_t i = 0; i < a.size(); ++i)
    input[3 * i] = a[i], input[3 * i + 1] = b[i], input[3 * i + 2] = skew.empty() ? 0u : uint32_t(skew[i]);
  return run_probe(device, validation, input, uint32_t(a.size()), a.size(), validation_messages);
}

}  // namespace st::gpu
