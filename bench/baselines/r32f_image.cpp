#include "bench/baselines/r32f_image.hpp"

#include <bit>
#include <cstring>
#include <vector>

#include "gpu/kernels.hpp"

namespace st::gpu {

namespace L = layout;

namespace {
const uint32_t kR32fSpv[] = {
#include "bench/baselines/r32f.comp.spv.inc"
};
const std::span<const uint32_t> kR32fKernel[] = {kR32fSpv};
}  // namespace

struct R32fImage::Impl {
  VkContext ctx;
  Kernels kernels;
  VkBufferBox image, page, input, normals, output, feedback;
  VkCommandPool pool = VK_NULL_HANDLE;
  VkCommandBuffer cmd = VK_NULL_HANDLE;
  VkFence fence = VK_NULL_HANDLE;
  VkQueryPool queries = VK_NULL_HANDLE;
  VkDescriptorSet set = VK_NULL_HANDLE;
  uint32_t level = 0, max_items = 0;

  Impl(const std::string& device, uint32_t l, std::span<const float> values, uint32_t max)
      : ctx(device, false), level(l), max_items(max) {
    try {
      const uint64_t bytes = values.size() * 4;
      if (values.size() != (uint64_t(1) << (2 * l))) throw GpuError("R32fImage: values must hold 4^level floats");
      if (bytes > ctx.properties().limits.maxStorageBufferRange)
        throw GpuError("R32fImage: " + std::to_string(bytes) + " bytes exceed maxStorageBufferRange of '" + ctx.device_name() + "'");
      kernels.create(ctx, 1, {}, kR32fKernel);
      image = ctx.make_buffer(bytes, false);
      const uint32_t pcf = L::kPtHeaderWords;
      page = ctx.make_buffer((pcf + L::kMaxPcf * L::kPcfTableStride) * 4, true);
      auto* p = static_cast<uint32_t*>(page.mapped);
      std::memset(p, 0, page.size);
      p[L::kPtMapLevel] = l;
      p[L::kPtPcfTable] = pcf;
      for (uint32_t r = 1; r <= L::kMaxPcf; ++r)
        for (uint32_t lit = 0; lit <= r * r; ++lit)
          p[pcf + (r - 1) * L::kPcfTableStride + lit] = std::bit_cast<uint32_t>(float(lit) / float(r * r));
      input = ctx.make_buffer(uint64_t(max) * 24 > uint64_t(max) * 16 ? uint64_t(max) * 24 : uint64_t(max) * 16, true);
      normals = ctx.make_buffer(uint64_t(max) * 16, true);
      output = ctx.make_buffer(uint64_t(max) * 4, true);
      feedback = ctx.make_buffer(64, true);
      set = kernels.bind(ctx, 0, {image.buffer, page.buffer, input.buffer, normals.buffer, output.buffer, feedback.buffer});
      pool = ctx.make_command_pool(true);
      cmd = ctx.allocate_command_buffer(pool);
      fence = ctx.make_fence();
      queries = ctx.make_timestamp_queries(2);
      // The image goes up in chunks through the (host-visible) normals buffer.
      const uint64_t chunk = normals.size;
      for (uint64_t off = 0; off < bytes; off += chunk) {
        const uint64_t n = std::min(chunk, bytes - off);
        std::memcpy(normals.mapped, reinterpret_cast<const uint8_t*>(values.data()) + off, n);
        begin();
        VkBufferCopy c{0, off, n};
        ctx.vk.CmdCopyBuffer(cmd, normals.buffer, image.buffer, 1, &c);
        submit();
      }
    } catch (...) {
      release();
      throw;
    }
  }
  ~Impl() { release(); }

  void release() noexcept {
    ctx.vk.DeviceWaitIdle(ctx.device());
    if (queries) ctx.vk.DestroyQueryPool(ctx.device(), queries, nullptr);
    if (fence) ctx.vk.DestroyFence(ctx.device(), fence, nullptr);
    if (pool) ctx.vk.DestroyCommandPool(ctx.device(), pool, nullptr);
    queries = VK_NULL_HANDLE, fence = VK_NULL_HANDLE, pool = VK_NULL_HANDLE;
    for (VkBufferBox* b : {&image, &page, &input, &normals, &output, &feedback}) ctx.destroy(*b);
    kernels.destroy(ctx);
  }

  void begin() {
    vk_check(ctx.vk.ResetCommandBuffer(cmd, 0), "vkResetCommandBuffer");
    VkCommandBufferBeginInfo bi{};
    bi.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO;
    bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
    vk_check(ctx.vk.BeginCommandBuffer(cmd, &bi), "vkBeginCommandBuffer");
  }
  void submit() {
    vk_check(ctx.vk.EndCommandBuffer(cmd), "vkEndCommandBuffer");
    VkSubmitInfo si{};
    si.sType = VK_STRUCTURE_TYPE_SUBMIT_INFO;
    si.commandBufferCount = 1;
    si.pCommandBuffers = &cmd;
    vk_check(ctx.vk.QueueSubmit(ctx.queue(), 1, &si, fence), "vkQueueSubmit");
    vk_check(ctx.vk.WaitForFences(ctx.device(), 1, &fence, VK_TRUE, UINT64_MAX), "vkWaitForFences");
    vk_check(ctx.vk.ResetFences(ctx.device(), 1, &fence), "vkResetFences");
  }

  double run(const uint32_t (&pc)[L::kPcWords], uint32_t n, std::span<float> out) {
    begin();
    VkMemoryBarrier raw{};
    raw.sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER;
    raw.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT | VK_ACCESS_HOST_WRITE_BIT;
    raw.dstAccessMask = VK_ACCESS_SHADER_READ_BIT;
    ctx.vk.CmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT | VK_PIPELINE_STAGE_HOST_BIT, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
                         0, 1, &raw, 0, nullptr, 0, nullptr);
    if (queries) ctx.vk.CmdResetQueryPool(cmd, queries, 0, 2);
    kernels.record(cmd, extra_kernel(0), set, pc);
    if (queries) ctx.vk.CmdWriteTimestamp(cmd, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, queries, 0);
    ctx.vk.CmdDispatch(cmd, (n + L::kWorkgroupSize - 1) / L::kWorkgroupSize, 1, 1);
    if (queries) ctx.vk.CmdWriteTimestamp(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, queries, 1);
    VkMemoryBarrier host{};
    host.sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER;
    host.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT;
    host.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
    ctx.vk.CmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_PIPELINE_STAGE_HOST_BIT, 0, 1, &host, 0, nullptr, 0, nullptr);
    submit();
    std::memcpy(out.data(), output.mapped, size_t(n) * 4);
    if (!queries) return 0;
    uint64_t ts[2] = {0, 0};
    vk_check(ctx.vk.GetQueryPoolResults(ctx.device(), queries, 0, 2, sizeof(ts), ts, 8, VK_QUERY_RESULT_64_BIT | VK_QUERY_RESULT_WAIT_BIT),
             "vkGetQueryPoolResults");
    const uint32_t bits = ctx.timestamp_bits();
    const uint64_t mask = bits >= 64 ? ~uint64_t(0) : (uint64_t(1) << bits) - 1;
    return double((ts[1] - ts[0]) & mask) * ctx.properties().limits.timestampPeriod * 1e-6;
  }
};

R32fImage::R32fImage(const std::string& device, uint32_t level, std::span<const float> values, uint32_t max_items)
    : impl_(std::make_unique<Impl>(device, level, values, max_items)) {}
R32fImage::~R32fImage() = default;

double R32fImage::evaluate(std::span<const GpuQuery> queries, std::span<float> out) {
  Impl& m = *impl_;
  if (queries.size() > m.max_items || out.size() < queries.size()) throw GpuError("R32fImage::evaluate: too many queries");
  static_assert(sizeof(GpuQuery) == L::kQueryWords * 4);
  std::memcpy(m.input.mapped, queries.data(), queries.size() * sizeof(GpuQuery));
  uint32_t pc[L::kPcWords] = {};
  pc[L::kPcCount] = uint32_t(queries.size());
  return m.run(pc, uint32_t(queries.size()), out);
}

double R32fImage::shadow_pass(const ShadowPassInput& in, const ShadowLight& light, std::span<float> out) {
  Impl& m = *impl_;
  const uint64_t pixels = uint64_t(in.width) * in.height;
  if (pixels > m.max_items || out.size() < pixels || in.positions.size() < pixels * 4 || in.normals.size() < pixels * 4)
    throw GpuError("R32fImage::shadow_pass: image larger than max_items or buffers too small");
  std::memcpy(m.input.mapped, in.positions.data(), pixels * 16);
  std::memcpy(m.normals.mapped, in.normals.data(), pixels * 16);
  uint32_t pc[L::kPcWords] = {};
  pc[L::kPcCount] = in.width;
  pc[L::kPcHeight] = in.height;
  pc[L::kPcKernel] = in.kernel;
  pc[L::kPcFlags] = 2;
  for (int i = 0; i < 3; ++i) {
    pc[L::kPcOrigin + i] = std::bit_cast<uint32_t>(light.origin[i]);
    pc[L::kPcAxisU + i] = std::bit_cast<uint32_t>(light.axis_u[i]);
    pc[L::kPcAxisV + i] = std::bit_cast<uint32_t>(light.axis_v[i]);
    pc[L::kPcForward + i] = std::bit_cast<uint32_t>(light.forward[i]);
  }
  pc[L::kPcNear] = std::bit_cast<uint32_t>(light.near_scaled);
  pc[L::kPcNormalOffset] = std::bit_cast<uint32_t>(in.normal_offset);
  return m.run(pc, uint32_t(pixels), out);
}

}  // namespace st::gpu
