// Deep shadow tiles: validation and lookups (deep_tile.hpp, DEEP.md).
#include "tiles/core/deep_tile.hpp"

#include <algorithm>
#include <bit>
#include <cmath>

#include "common/bytes.hpp"
#include "common/error.hpp"

namespace st {
namespace {

using namespace deep;

float depth_at(const uint8_t* depths, uint32_t i) { return load_le<float>(depths + 4 * size_t(i)); }
// q / 65535 as float(q) times the float nearest 1 / 65535 (0x37800080), one correctly
// rounded product that a shader forms with the same bits (Vulkan's multiply is IEEE's;
// no division, whose GPU precision is 2.5 ulp): within one ulp of the quotient, monotone
// in q, exactly 0 and 1 at q = 0 and 65535.
float value_at(const uint8_t* values, uint32_t i) {
  return float(load_le<uint16_t>(values + 2 * size_t(i))) * kUnormInverse;
}

// Depths of magnitude below 2^-103 read as 0: every other float is then a multiple of
// 2^-126, so the difference of two of them is 0 or a normal float, and the lookup never
// forms a subnormal that a device flushing them (shaderDenormPreserveFloat32 = false)
// would answer differently (gpu/GPU_LAYOUT.md "Exactness").
float flush_depth(float d) { return std::fabs(d) < deep::kDepthFlushBelow ? 0.0f : d; }

}  // namespace

DeepTileView DeepTileView::open(std::span<const uint8_t> b, const std::string& what) {
  auto fail = [&](const std::string& why) -> void { throw FormatError(what + ": " + why); };
  if (b.size() < kHeaderBytes)
    fail("truncated: " + std::to_string(b.size()) + " bytes, the header needs 48");
  auto u32 = [&](size_t at) { return load_le<uint32_t>(b, at); };
  if (u32(0) != kMagic) fail("bad magic");
  if (u32(4) != kVersion) fail("version " + std::to_string(u32(4)) + " (this reader knows 1)");
  if (u32(8) != kHeaderBytes) fail("header_bytes is not 48");
  const uint32_t bits = u32(12);
  if (bits > kMaxSideBits) fail("side_bits " + std::to_string(bits) + " above 8");
  if (u32(16) != bits + 1) fail("mip_count is not side_bits + 1");
  const uint32_t texels = texel_count(bits);
  if (u32(20) != texels) fail("texel_count disagrees with side_bits");
  if (u32(24) != kHeaderBytes) fail("directory_offset is not 48");
  const uint64_t data_offset = kHeaderBytes + 8ull * texels;
  if (u32(28) != data_offset) fail("data_offset disagrees with texel_count");
  const uint32_t data_bytes = u32(32);
  if (uint64_t(u32(36)) != data_offset + data_bytes) fail("total_bytes is not data_offset + data_bytes");
  if (b.size() < data_offset + data_bytes)
    fail("truncated: " + std::to_string(b.size()) + " bytes of " +
         std::to_string(data_offset + data_bytes));
  if (b.size() > data_offset + data_bytes) fail("trailing bytes after total_bytes");
  const float eps = load_le<float>(b, 40);
  if (!(std::isfinite(eps) && eps >= 0)) fail("epsilon is not finite and >= 0");
  if (u32(44) != 0) fail("reserved header field is not 0");

  const uint8_t* dir = b.data() + kHeaderBytes;
  const uint8_t* data = b.data() + data_offset;
  uint64_t expect = 0;
  for (uint32_t i = 0; i < texels; ++i) {
    const uint8_t* e = dir + 8 * size_t(i);
    const std::string at = "texel " + std::to_string(i);
    const uint32_t offset = load_le<uint32_t>(e);
    const uint32_t n = load_le<uint16_t>(e + 4);
    const uint8_t flags = e[6];
    if (e[7] != 0 || (flags & ~kFlagMonochrome) != 0) fail(at + ": unknown flags");
    if (offset != expect) fail(at + ": offset out of order");
    const bool mono = flags & kFlagMonochrome;
    const uint32_t bytes = block_bytes(n, mono);
    if (expect + bytes > data_bytes) fail(at + ": block runs past data_bytes");
    const uint8_t* depths = data + offset;
    const uint8_t* values = depths + 4 * size_t(n);
    const uint32_t c = mono ? 1 : 3;
    for (uint32_t k = 0; k < n; ++k) {
      const float z = depth_at(depths, k);
      if (!std::isfinite(z)) fail(at + ": depth not finite");
      if (k > 0 && z < depth_at(depths, k - 1)) fail(at + ": depth decreases");
      if (k > 1 && z == depth_at(depths, k - 2)) fail(at + ": more than two vertices at one depth");
      for (uint32_t ch = 0; ch < c && k > 0; ++ch)
        if (load_le<uint16_t>(values + 2 * size_t(k * c + ch)) >
            load_le<uint16_t>(values + 2 * size_t((k - 1) * c + ch)))
          fail(at + ": transmittance increases");
    }
    for (uint32_t p = 4 * n + 2 * n * c; p < bytes; ++p)
      if (depths[p] != 0) fail(at + ": padding is not 0");
    expect += bytes;
  }
  if (expect != data_bytes) fail("data_bytes is not the sum of the texel blocks");
  DeepTileView v;
  v.dir_ = dir;
  v.data_ = data;
  v.side_bits_ = bits;
  v.epsilon_ = eps;
  return v;
}

DeepTileView::Texel DeepTileView::texel(uint32_t x, uint32_t y, uint32_t mip) const {
  const uint32_t s = side(mip);
  const uint8_t* e = dir_ + 8 * size_t(mip_base(side_bits_, mip) + y * s + x);
  const uint32_t n = load_le<uint16_t>(e + 4);
  const uint8_t* depths = data_ + load_le<uint32_t>(e);
  return {depths, depths + 4 * size_t(n), n, (e[6] & kFlagMonochrome) != 0};
}

std::array<float, 3> DeepTileView::eval(const Texel& t, float z) {
  if (t.n == 0) return {1, 1, 1};
  const uint32_t c = t.mono ? 1 : 3;
  auto value = [&](uint32_t k) -> std::array<float, 3> {
    const float r = value_at(t.values, k * c);
    if (t.mono) return {r, r, r};
    return {r, value_at(t.values, k * c + 1), value_at(t.values, k * c + 2)};
  };
  // Float arithmetic a shader repeats bit for bit (gpu/shaders/st_deep.glsl): depths and
  // the receiver's depth read through flush_depth, then one rounding per operation (this
  // file is built without contraction). k: the first vertex at depth >= z (a receiver at a
  // step's depth sees the value before).
  const float zf = flush_depth(z);
  uint32_t lo = 0, hi = t.n;
  while (lo < hi) {
    const uint32_t m = lo + (hi - lo) / 2;
    if (flush_depth(depth_at(t.depths, m)) < zf) lo = m + 1;
    else hi = m;
  }
  if (lo == 0) return value(0);
  if (lo == t.n) return value(t.n - 1);
  const float za = flush_depth(depth_at(t.depths, lo - 1)), zb = flush_depth(depth_at(t.depths, lo));
  const float f = std::clamp((zf - za) / (zb - za), 0.0f, 1.0f);
  const auto a = value(lo - 1), b = value(lo);
  // Clamped to the segment's two values: b - a rounds, so a + (b - a) * f could pass b by
  // an ulp at f near 1 and the next segment (starting at b exactly) would rise; clamped,
  // the function stays non-increasing in z as the vertices are (min/max round nothing).
  std::array<float, 3> r;
  for (int ch = 0; ch < 3; ++ch)
    r[ch] = std::clamp(a[ch] + (b[ch] - a[ch]) * f, std::min(a[ch], b[ch]), std::max(a[ch], b[ch]));
  return r;
}

std::array<float, 3> DeepTileView::transmittance(uint32_t x, uint32_t y, float z, uint32_t mip) const {
  return eval(texel(x, y, mip), z);
}

uint32_t DeepTileView::vertex_count(uint32_t x, uint32_t y, uint32_t mip) const {
  return texel(x, y, mip).n;
}

bool DeepTileView::monochrome(uint32_t x, uint32_t y, uint32_t mip) const {
  return texel(x, y, mip).mono;
}

// The filters run in float, one rounding per operation, in the order written (this file
// is built without contraction): gpu/shaders/st_deep.glsl repeats them bit for bit. No
// step forms a subnormal: positions are multiples of 2^-24 texels or 0, weights and values
// 0 or at least 2^-41 (DEEP.md "Lookups").
std::array<float, 3> DeepTileView::bilinear_f(float u, float v, float z, uint32_t mip) const {
  const uint32_t s = side(mip);
  const float last = float(s - 1);
  auto axis = [&](float w, uint32_t& i0, uint32_t& i1, float& f) {
    float p = w * float(s) - 0.5f;
    if (!(p > 0.0f)) p = 0.0f;  // also NaN
    if (p > last) p = last;
    i0 = uint32_t(p);
    i1 = std::min(i0 + 1, s - 1);
    f = p - float(i0);
  };
  uint32_t x0, x1, y0, y1;
  float fx, fy;
  axis(u, x0, x1, fx);
  axis(v, y0, y1, fy);
  const auto a = eval(texel(x0, y0, mip), z), b = eval(texel(x1, y0, mip), z);
  const auto c = eval(texel(x0, y1, mip), z), d = eval(texel(x1, y1, mip), z);
  const float gx = 1.0f - fx, gy = 1.0f - fy;
  std::array<float, 3> r;
  for (int ch = 0; ch < 3; ++ch) {
    const float top = a[ch] * gx + b[ch] * fx;
    const float bottom = c[ch] * gx + d[ch] * fx;
    r[ch] = top * gy + bottom * fy;
  }
  return r;
}

std::array<float, 3> DeepTileView::mip_blend(float u, float v, float z, uint32_t m0, float f) const {
  const auto a = bilinear_f(u, v, z, m0);
  if (f == 0.0f || m0 >= side_bits_) return a;
  const auto b = bilinear_f(u, v, z, m0 + 1);
  const float g = 1.0f - f;
  std::array<float, 3> r;
  for (int ch = 0; ch < 3; ++ch) r[ch] = a[ch] * g + b[ch] * f;
  return r;
}

std::array<float, 3> DeepTileView::bilinear(double u, double v, float z, uint32_t mip) const {
  return bilinear_f(float(u), float(v), z, mip);
}

std::array<float, 3> DeepTileView::trilinear(double u, double v, float z, double lod) const {
  if (!(lod >= 0)) lod = 0;  // also NaN
  lod = std::min(lod, double(side_bits_));
  const uint32_t m0 = uint32_t(lod);
  return mip_blend(float(u), float(v), z, m0, float(lod - m0));
}

std::array<float, 3> DeepTileView::filtered(double u, double v, float z, double width) const {
  // texels = width * side(0); lod = e + (m - 1) for texels = m * 2^e, m in [1, 2): log2
  // linear between powers of two (exact at them, never off by more than 0.086), formed
  // from the float's bits so a shader gets the same mip pair and weight.
  const float texels = float(width * double(side(0)));
  uint32_t m0 = 0;
  float f = 0.0f;
  if (texels > 1.0f) {  // also not NaN
    const uint32_t bits = std::bit_cast<uint32_t>(texels);
    const uint32_t e = (bits >> 23) - 127;  // >= 0: texels > 1
    if (e >= side_bits_) m0 = side_bits_;
    else m0 = e, f = float(bits & 0x7FFFFFu) * 0x1p-23f;
  }
  return mip_blend(float(u), float(v), z, m0, f);
}

VisibilityFunction DeepTileView::function(uint32_t x, uint32_t y, uint32_t mip) const {
  const Texel t = texel(x, y, mip);
  VisibilityFunction f;
  f.monochrome = t.mono;
  const uint32_t c = t.mono ? 1 : 3;
  for (uint32_t k = 0; k < t.n; ++k) {
    VisVertex v;
    v.depth = depth_at(t.depths, k);
    for (int ch = 0; ch < 3; ++ch) v.t[ch] = value_at(t.values, k * c + (t.mono ? 0 : uint32_t(ch)));
    f.vertices.push_back(v);
  }
  return f;
}

}  // namespace st
