// Deep shadow maps as deep scanline OpenEXR files: see deep_exr.hpp.
#include "tiles/bake/deep_exr.hpp"

#include <ImfChannelList.h>
#include <ImfCompositeDeepScanLine.h>
#include <ImfFrameBuffer.h>
#include <ImfDeepFrameBuffer.h>
#include <ImfDeepScanLineInputFile.h>
#include <ImfDeepScanLineOutputFile.h>
#include <ImfHeader.h>
#include <ImfIntAttribute.h>
#include <ImfPartType.h>
#include <ImfStringAttribute.h>
#include <ImfTestFile.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <filesystem>

#include "common/error.hpp"

namespace st {
namespace {

constexpr const char* kAttrDeep = "shadowtile.deep";
constexpr const char* kAttrLevel = "shadowtile.level";
constexpr const char* kAttrX0 = "shadowtile.x0";
constexpr const char* kAttrY0 = "shadowtile.y0";
constexpr const char* kAttrEpsilon = "shadowtile.epsilon";
constexpr const char* kAttrSamples = "shadowtile.samples";
constexpr const char* kAttrLight = "shadowtile.light";
constexpr const char* kAttrScene = "shadowtile.scene";
constexpr uint64_t kMaxSide = 16384;

struct Sample {
  float z, zb, a[3];
};

// The deep samples of one function (deep_exr.hpp "samples").
void samples_of(const VisibilityFunction& f, std::vector<Sample>& out) {
  const auto& vs = f.vertices;
  if (vs.empty()) return;
  auto alpha = [](float before, float after) {
    return before > 0 ? std::clamp(1.0f - after / before, 0.0f, 1.0f) : 1.0f;
  };
  if (vs[0].t != std::array<float, 3>{1, 1, 1})
    out.push_back({vs[0].depth, vs[0].depth, {1 - vs[0].t[0], 1 - vs[0].t[1], 1 - vs[0].t[2]}});
  for (size_t i = 0; i + 1 < vs.size(); ++i) {
    const VisVertex &a = vs[i], &b = vs[i + 1];
    if (a.t == b.t) continue;
    if (a.t[0] == 0 && a.t[1] == 0 && a.t[2] == 0) break;
    out.push_back({a.depth, b.depth, {alpha(a.t[0], b.t[0]), alpha(a.t[1], b.t[1]), alpha(a.t[2], b.t[2])}});
  }
}

const char* const kColour[3] = {"AR", "AG", "AB"};

// OpenEXR's deep slices over `samples` (counts[i] of them for pixel i, pixel after pixel):
// each channel holds a pointer a pixel to its first sample's value, samples sizeof(Sample)
// apart; a pixel without samples points at `dummy`. One layout for the writer and the reader.
struct SampleSlices {
  std::vector<char*> z, zb, a[3];
  Sample dummy{};
  SampleSlices(std::vector<Sample>& samples, const std::vector<unsigned>& counts)
      : z(counts.size()), zb(counts.size()) {
    for (auto& v : a) v.resize(counts.size());
    size_t at = 0;
    for (size_t i = 0; i < counts.size(); ++i) {
      Sample* s = counts[i] ? &samples[at] : &dummy;
      at += counts[i];
      z[i] = reinterpret_cast<char*>(&s->z);
      zb[i] = reinterpret_cast<char*>(&s->zb);
      for (int c = 0; c < 3; ++c) a[c][i] = reinterpret_cast<char*>(&s->a[c]);
    }
  }
  SampleSlices(const SampleSlices&) = delete;  // the pointers may point at `dummy`
  // Z, ZBack where the file has it, and AR/AG/AB (colour) or A, for rows `width` pixels wide.
  void insert_into(Imf::DeepFrameBuffer& fb, size_t width, bool has_back, bool colour) {
    const size_t xs = sizeof(char*), ys = xs * width;
    auto slice = [&](std::vector<char*>& v) {
      return Imf::DeepSlice(Imf::FLOAT, reinterpret_cast<char*>(v.data()), xs, ys, sizeof(Sample));
    };
    fb.insert("Z", slice(z));
    if (has_back) fb.insert("ZBack", slice(zb));
    if (colour)
      for (int c = 0; c < 3; ++c) fb.insert(kColour[c], slice(a[c]));
    else
      fb.insert("A", slice(a[0]));
  }
};

}  // namespace

void write_deep_exr(const std::string& path, const DeepRegion& region, double epsilon) {
  DeepExrInfo info;
  info.epsilon = epsilon;
  write_deep_exr(path, region, info);
}

void write_deep_exr(const std::string& path, const DeepRegion& region, const DeepExrInfo& info) {
  const double epsilon = info.epsilon;
  const TraceRegion& r = region.region;
  if (r.width == 0 || r.height == 0 || r.width > kMaxSide || r.height > kMaxSide ||
      region.functions.size() != size_t(r.width) * r.height)
    throw Error(path + ": cannot write an empty, oversized or inconsistent deep region");
  bool colour = false;
  for (const VisibilityFunction& f : region.functions) colour = colour || !f.monochrome;
  std::vector<Sample> samples;
  std::vector<unsigned> counts(region.functions.size());
  for (size_t i = 0; i < region.functions.size(); ++i) {
    const size_t first = samples.size();
    samples_of(region.functions[i], samples);
    counts[i] = unsigned(samples.size() - first);
  }
  SampleSlices slices(samples, counts);
  Imf::Header h(int(r.width), int(r.height));
  h.setType(Imf::DEEPSCANLINE);
  h.compression() = Imf::ZIPS_COMPRESSION;
  h.channels().insert("Z", Imf::Channel(Imf::FLOAT));
  h.channels().insert("ZBack", Imf::Channel(Imf::FLOAT));
  if (colour)
    for (const char* c : kColour) h.channels().insert(c, Imf::Channel(Imf::FLOAT));
  else
    h.channels().insert("A", Imf::Channel(Imf::FLOAT));
  h.insert(kAttrDeep, Imf::IntAttribute(kDeepExrFormatVersion));
  h.insert(kAttrLevel, Imf::IntAttribute(int(r.level)));
  h.insert(kAttrX0, Imf::IntAttribute(int(r.x0)));
  h.insert(kAttrY0, Imf::IntAttribute(int(r.y0)));
  if (epsilon >= 0) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.9g", epsilon);
    h.insert(kAttrEpsilon, Imf::StringAttribute(buf));
  }
  if (info.samples_per_side > 0) h.insert(kAttrSamples, Imf::IntAttribute(int(info.samples_per_side)));
  if (!info.light.empty()) h.insert(kAttrLight, Imf::StringAttribute(info.light));
  if (!info.scene_hash.empty()) h.insert(kAttrScene, Imf::StringAttribute(info.scene_hash));
  Imf::DeepFrameBuffer fb;
  fb.insertSampleCountSlice(Imf::Slice(Imf::UINT, reinterpret_cast<char*>(counts.data()),
                                       sizeof(unsigned), sizeof(unsigned) * r.width));
  slices.insert_into(fb, r.width, true, colour);
  const std::string tmp = path + ".tmp";
  try {
    Imf::DeepScanLineOutputFile out(tmp.c_str(), h);
    out.setFrameBuffer(fb);
    out.writePixels(int(r.height));
  } catch (const std::exception& e) {
    std::error_code ec;
    std::filesystem::remove(tmp, ec);
    throw Error(path + ": writing the deep EXR failed: " + e.what());
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::filesystem::remove(tmp, ec);
    throw Error(path + ": cannot rename the finished deep EXR into place: " + ec.message());
  }
}

DeepRegion read_deep_exr(const std::string& path, DeepExrInfo* info, uint64_t max_texels) {
  auto fail = [&](const std::string& why) -> void { throw FormatError(path + ": " + why); };
  DeepRegion out;
  bool tiled = false, is_deep = false, multi = false;
  if (Imf::isOpenExrFile(path.c_str(), tiled, is_deep, multi) && (!is_deep || tiled))
    fail(std::string("a ") + (is_deep ? "deep tiled" : "flat (not deep)") +
         " OpenEXR image; a deep shadow map is read from a deep scanline EXR (as `shadowtile export --deep` writes)");
  try {
    Imf::DeepScanLineInputFile in(path.c_str());
    const Imf::Header& h = in.header();
    const auto* deep = h.findTypedAttribute<Imf::IntAttribute>(kAttrDeep);
    if (deep && deep->value() != kDeepExrFormatVersion)
      fail("shadowtile deep EXR version " + std::to_string(deep->value()) + " (this reader knows " +
           std::to_string(kDeepExrFormatVersion) + ")");
    const bool foreign = deep == nullptr;  // another tool's deep image
    auto int_attr = [&](const char* name) {
      const auto* a = h.findTypedAttribute<Imf::IntAttribute>(name);
      if (!a || a->value() < 0) fail(std::string("missing or negative int attribute ") + name);
      return uint64_t(a->value());
    };
    const auto dw = h.dataWindow();
    if (dw.min.x != 0 || dw.min.y != 0) fail("data window does not start at (0, 0)");
    const uint64_t w = uint64_t(int64_t(dw.max.x) + 1), hh = uint64_t(int64_t(dw.max.y) + 1);
    if (w == 0 || hh == 0 || w > kMaxSide || hh > kMaxSide) fail("data window is empty or too large");
    if (w * hh > max_texels)
      fail("data window of " + std::to_string(w) + "x" + std::to_string(hh) + " texels exceeds " +
           std::to_string(max_texels));
    TraceRegion& r = out.region;
    if (foreign) {  // the whole map of the level its square, power-of-two window gives
      if (w != hh || (w & (w - 1)) != 0)
        fail("data window " + std::to_string(w) + "x" + std::to_string(hh) +
             " is not a square power of two (a deep EXR without shadowtile attributes must hold a whole map)");
      r.level = uint32_t(std::countr_zero(w));
      r.x0 = r.y0 = 0;
    } else {
      r.level = uint32_t(std::min<uint64_t>(int_attr(kAttrLevel), 99));
      r.x0 = int_attr(kAttrX0), r.y0 = int_attr(kAttrY0);
    }
    r.width = uint32_t(w), r.height = uint32_t(hh);
    if (info) {
      *info = {};
      if (const auto* a = h.findTypedAttribute<Imf::StringAttribute>(kAttrEpsilon)) {
        char* end = nullptr;
        const double e = std::strtod(a->value().c_str(), &end);
        if (end == a->value().c_str() || *end != 0 || !(e >= 0 && e <= 1)) fail("shadowtile.epsilon is not a number in [0, 1]");
        info->epsilon = e;
      }
      if (const auto* a = h.findTypedAttribute<Imf::IntAttribute>(kAttrSamples)) {
        if (a->value() < 1 || a->value() > 64) fail("shadowtile.samples is not in 1..64");
        info->samples_per_side = uint32_t(a->value());
      }
      if (const auto* a = h.findTypedAttribute<Imf::StringAttribute>(kAttrLight)) info->light = a->value();
      if (const auto* a = h.findTypedAttribute<Imf::StringAttribute>(kAttrScene)) info->scene_hash = a->value();
      info->foreign = foreign;
    }
    if (r.level > kMaxLevel || r.x0 + w > (uint64_t(1) << r.level) || r.y0 + hh > (uint64_t(1) << r.level))
      fail("region lies outside its level's map");
    const Imf::ChannelList& ch = h.channels();
    auto need = [&](const char* name, bool half_too) {
      const Imf::Channel* c = ch.findChannel(name);
      if (!c || !(c->type == Imf::FLOAT || (half_too && c->type == Imf::HALF)))
        fail(std::string("channel ") + name + " missing or not " + (half_too ? "FLOAT or HALF" : "FLOAT"));
    };
    need("Z", false);
    // ZBack may be absent: every sample is then a point sample (OpenEXR's rule).
    const bool has_back = ch.findChannel("ZBack") != nullptr;
    if (has_back) need("ZBack", false);
    const bool colour = ch.findChannel("A") == nullptr;
    if (colour)
      for (const char* c : kColour) need(c, true);
    else
      need("A", true);
    const size_t n = size_t(w) * hh;
    std::vector<unsigned> counts(n);
    Imf::DeepFrameBuffer fb;
    fb.insertSampleCountSlice(Imf::Slice(Imf::UINT, reinterpret_cast<char*>(counts.data()),
                                         sizeof(unsigned), sizeof(unsigned) * w));
    in.setFrameBuffer(fb);
    in.readPixelSampleCounts(0, int(hh) - 1);
    uint64_t total = 0;
    for (unsigned c : counts) total += c;
    if (total > kMaxDeepExrSamples) fail("more than 2^28 deep samples");
    std::vector<Sample> samples(total);
    SampleSlices slices(samples, counts);
    slices.insert_into(fb, w, has_back, colour);
    // A new frame buffer forgets the counts: read them again (the same values) first.
    // The sample pointers were laid out for these counts: they must not change.
    const std::vector<unsigned> laid_out = counts;
    in.setFrameBuffer(fb);
    in.readPixelSampleCounts(0, int(hh) - 1);
    if (counts != laid_out) fail("sample counts changed between two reads");
    in.readPixels(0, int(hh) - 1);
    // Rebuild each function front to back: T drops by (1 - alpha) across each sample.
    out.functions.resize(n);
    size_t at = 0;
    for (size_t i = 0; i < n; ++i) {
      VisibilityFunction& f = out.functions[i];
      f.monochrome = !colour;
      std::array<float, 3> t{1, 1, 1};
      float last = -INFINITY;
      auto push = [&](float d) {
        const VisVertex v{d, t};
        const size_t k = f.vertices.size();
        if (k && f.vertices[k - 1] == v) return;
        // Of a run at one depth keep the first and the last (values only fall).
        if (k >= 2 && f.vertices[k - 1].depth == d && f.vertices[k - 2].depth == d) f.vertices.pop_back();
        f.vertices.push_back(v);
      };
      for (unsigned k = 0; k < counts[i]; ++k, ++at) {
        Sample s = samples[at];
        if (!colour) s.a[1] = s.a[2] = s.a[0];
        if (!has_back) s.zb = s.z;
        if (!std::isfinite(s.z) || !std::isfinite(s.zb) || s.zb < s.z || s.z < last)
          fail("texel " + std::to_string(i) + ": samples unsorted, overlapping or not finite");
        for (float al : s.a)
          if (!(al >= 0 && al <= 1)) fail("texel " + std::to_string(i) + ": alpha outside [0, 1]");
        last = s.zb;
        push(s.z);
        for (int c = 0; c < 3; ++c) t[c] = std::min(t[c], t[c] * (1 - s.a[c]));
        push(s.zb);
      }
      if (const std::string why = f.check(); !why.empty()) fail("texel " + std::to_string(i) + ": " + why);
    }
  } catch (const FormatError&) {
    throw;
  } catch (const std::exception& e) {
    throw FormatError(path + ": reading the deep EXR failed: " + e.what());
  }
  return out;
}

std::vector<float> composite_deep_exr_alpha(const std::string& path) {
  try {
    Imf::DeepScanLineInputFile in(path.c_str());
    if (!in.header().channels().findChannel("A"))
      throw FormatError(path + ": a coloured deep EXR has no A channel to composite");
    const auto dw = in.header().dataWindow();
    if (dw.min.x != 0 || dw.min.y != 0 || dw.max.x < 0 || dw.max.y < 0 ||
        uint64_t(dw.max.x) >= kMaxSide || uint64_t(dw.max.y) >= kMaxSide)
      throw FormatError(path + ": data window is empty, too large or not at (0, 0)");
    const size_t w = size_t(dw.max.x) + 1, h = size_t(dw.max.y) + 1;
    std::vector<float> alpha(w * h, 0.0f);
    Imf::CompositeDeepScanLine comp;
    comp.addSource(&in);
    Imf::FrameBuffer fb;
    fb.insert("A", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(alpha.data()), sizeof(float),
                              sizeof(float) * w));
    comp.setFrameBuffer(fb);
    comp.readPixels(0, int(h) - 1);
    return alpha;
  } catch (const FormatError&) {
    throw;
  } catch (const std::exception& e) {
    throw FormatError(path + ": compositing the deep EXR failed: " + e.what());
  }
}

}  // namespace st
