// Depth-interval maps as OpenEXR files: see exr_io.hpp for the layout.
#include "image/exr_io.hpp"

#include <Iex.h>
#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfIntAttribute.h>
#include <ImfOutputFile.h>
#include <ImfStringAttribute.h>
#include <ImfThreading.h>
#include <ImfTiledOutputFile.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <sstream>
#include <thread>

#include "common/error.hpp"

namespace st {
namespace {

constexpr char kAttrFormat[] = "shadowtile.format";
constexpr char kAttrLevel[] = "shadowtile.level";
constexpr char kAttrX0[] = "shadowtile.x0";
constexpr char kAttrY0[] = "shadowtile.y0";
constexpr char kAttrLight[] = "shadowtile.light";
constexpr char kAttrLightSpace[] = "shadowtile.lightspace";

void use_threads() {
  static const bool once = [] {
    Imf::setGlobalThreadCount(int(std::max(1u, std::thread::hardware_concurrency())));
    return true;
  }();
  (void)once;
}

std::string encode_light_space(const LightSpace& ls) {
  std::string out = light_kind_name(ls.kind());
  char buf[40];
  for (double v : ls.to_array()) {
    std::snprintf(buf, sizeof buf, " %.17g", v);
    out += buf;
  }
  return out;
}

LightSpace decode_light_space(const std::string& path, const std::string& text) {
  std::istringstream is(text);
  std::string kind;
  is >> kind;
  // The names light_kind_name gives the kinds this build knows (the encoder writes them).
  uint8_t code = 0;
  while (light_kind_known(code) && kind != light_kind_name(LightKind(code))) ++code;
  if (!light_kind_known(code))
    throw FormatError(path + ": attribute " + kAttrLightSpace + ": unknown light kind '" + kind + "'");
  const LightKind lk = LightKind(code);
  std::array<double, 18> a{};
  for (size_t i = 0; i < a.size(); ++i) {
    std::string tok;
    if (!(is >> tok))
      throw FormatError(path + ": attribute " + kAttrLightSpace + ": expected 18 numbers");
    char* end = nullptr;
    a[i] = std::strtod(tok.c_str(), &end);
    if (end != tok.c_str() + tok.size() || !std::isfinite(a[i]))
      throw FormatError(path + ": attribute " + kAttrLightSpace + ": bad number '" + tok + "'");
  }
  std::string extra;
  if (is >> extra)
    throw FormatError(path + ": attribute " + kAttrLightSpace + ": trailing data '" + extra + "'");
  if (const std::string bad = LightSpace::check_array(lk, a); !bad.empty())
    throw FormatError(path + ": attribute " + kAttrLightSpace + ": " + bad);
  return LightSpace::from_array(lk, a);
}

Imf::FrameBuffer interval_frame_buffer(IntervalTile& tile) {
  Imf::FrameBuffer fb;
  const size_t xs = sizeof(Interval), ys = sizeof(Interval) * size_t(tile.width);
  fb.insert("lo", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(&tile.data[0].lo), xs, ys));
  fb.insert("hi", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(&tile.data[0].hi), xs, ys));
  return fb;
}

int required_int(const std::string& path, const Imf::Header& h, const char* name) {
  const auto* a = h.findTypedAttribute<Imf::IntAttribute>(name);
  if (!a) throw FormatError(path + ": missing int attribute " + name);
  return a->value();
}

}  // namespace

void write_interval_exr(const std::string& path, const IntervalTile& tile,
                        const ExrLightInfo& light) {
  if (tile.width == 0 || tile.height == 0 ||
      tile.data.size() != size_t(tile.width) * tile.height)
    throw Error(path + ": cannot write an empty or inconsistent interval tile");
  if (tile.level > kMaxLevel || tile.x0 + tile.width > (uint64_t(1) << tile.level) ||
      tile.y0 + tile.height > (uint64_t(1) << tile.level))
    throw Error(path + ": tile region leaves its level-" + std::to_string(tile.level) + " map");
  use_threads();
  Imf::Header h(int(tile.width), int(tile.height));
  h.compression() = Imf::ZIP_COMPRESSION;
  h.channels().insert("lo", Imf::Channel(Imf::FLOAT));
  h.channels().insert("hi", Imf::Channel(Imf::FLOAT));
  h.insert(kAttrFormat, Imf::IntAttribute(kExrFormatVersion));
  h.insert(kAttrLevel, Imf::IntAttribute(int(tile.level)));
  h.insert(kAttrX0, Imf::IntAttribute(int(tile.x0)));
  h.insert(kAttrY0, Imf::IntAttribute(int(tile.y0)));
  if (!light.spec.empty()) h.insert(kAttrLight, Imf::StringAttribute(light.spec));
  if (light.space) h.insert(kAttrLightSpace, Imf::StringAttribute(encode_light_space(*light.space)));
  const bool tiled = tile.width > kExrScanlineMaxSide || tile.height > kExrScanlineMaxSide;
  if (tiled) h.setTileDescription(Imf::TileDescription(kExrTileSide, kExrTileSide, Imf::ONE_LEVEL));

  // OpenEXR only reads through the frame buffer; the const_cast never writes.
  IntervalTile& src = const_cast<IntervalTile&>(tile);
  const std::string tmp = path + ".tmp";
  try {
    if (tiled) {
      Imf::TiledOutputFile out(tmp.c_str(), h);
      out.setFrameBuffer(interval_frame_buffer(src));
      out.writeTiles(0, out.numXTiles() - 1, 0, out.numYTiles() - 1);
    } else {
      Imf::OutputFile out(tmp.c_str(), h);
      out.setFrameBuffer(interval_frame_buffer(src));
      out.writePixels(int(tile.height));
    }
  } catch (const std::exception& e) {
    std::error_code ec;
    std::filesystem::remove(tmp, ec);
    throw Error(path + ": writing the EXR failed: " + e.what());
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::filesystem::remove(tmp, ec);
    throw Error(path + ": cannot rename the finished EXR into place: " + ec.message());
  }
}

IntervalTile read_interval_exr(const std::string& path, ExrLightInfo* light) {
  use_threads();
  IntervalTile tile;
  try {
    Imf::InputFile in(path.c_str());
    const Imf::Header& h = in.header();
    const Imath::Box2i dw = h.dataWindow();
    if (dw.min.x != 0 || dw.min.y != 0)
      throw FormatError(path + ": dataWindow must start at 0,0");
    const int64_t w = int64_t(dw.max.x) + 1, ht = int64_t(dw.max.y) + 1;
    if (w <= 0 || ht <= 0 || uint64_t(w) * uint64_t(ht) > kExrMaxTexels)
      throw FormatError(path + ": dataWindow " + std::to_string(w) + "x" + std::to_string(ht) +
                        " is empty or larger than 16384^2 texels");
    for (const char* name : {"lo", "hi"}) {
      const Imf::Channel* c = h.channels().findChannel(name);
      if (!c) throw FormatError(path + ": missing channel '" + name + "'");
      if (c->type != Imf::FLOAT || c->xSampling != 1 || c->ySampling != 1)
        throw FormatError(path + ": channel '" + name + "' must be full-resolution FLOAT");
    }
    const int version = required_int(path, h, kAttrFormat);
    if (version != kExrFormatVersion)
      throw FormatError(path + ": " + kAttrFormat + " " + std::to_string(version) +
                        " is not the supported version " + std::to_string(kExrFormatVersion));
    const int level = required_int(path, h, kAttrLevel);
    const int x0 = required_int(path, h, kAttrX0), y0 = required_int(path, h, kAttrY0);
    if (level < 0 || uint32_t(level) > kMaxLevel)
      throw FormatError(path + ": " + kAttrLevel + " " + std::to_string(level) + " outside 0..20");
    const uint64_t side = uint64_t(1) << level;
    if (x0 < 0 || y0 < 0 || uint64_t(x0) + uint64_t(w) > side || uint64_t(y0) + uint64_t(ht) > side)
      throw FormatError(path + ": region " + std::to_string(x0) + "," + std::to_string(y0) + "," +
                        std::to_string(w) + "," + std::to_string(ht) + " leaves the level-" +
                        std::to_string(level) + " map");
    tile.level = uint32_t(level);
    tile.x0 = uint64_t(x0), tile.y0 = uint64_t(y0);
    tile.width = uint32_t(w), tile.height = uint32_t(ht);
    tile.data.assign(size_t(w) * size_t(ht), Interval{});
    in.setFrameBuffer(interval_frame_buffer(tile));
    in.readPixels(0, int(ht) - 1);
    if (light) {
      *light = ExrLightInfo{};
      if (const auto* a = h.findTypedAttribute<Imf::StringAttribute>(kAttrLight))
        light->spec = a->value();
      if (const auto* a = h.findTypedAttribute<Imf::StringAttribute>(kAttrLightSpace))
        light->space = decode_light_space(path, a->value());
    }
  } catch (const FormatError&) {
    throw;
  } catch (const Error& e) {
    throw FormatError(path + ": " + e.what());
  } catch (const std::exception& e) {
    // Iex exceptions (missing file, truncated or corrupt data) are std::exceptions.
    throw FormatError(path + ": cannot read the EXR: " + e.what());
  }
  return tile;
}

bool exr_is_tiled(const std::string& path) {
  try {
    Imf::InputFile in(path.c_str());
    return in.header().hasTileDescription();
  } catch (const std::exception& e) {
    throw FormatError(path + ": cannot read the EXR: " + e.what());
  }
}

}  // namespace st
