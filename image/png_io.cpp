// PNG output through libpng's simplified API (png_image_*: no setjmp/longjmp in our code).
#include "image/png_io.hpp"

#include <png.h>

#include <algorithm>
#include <cstring>
#include <filesystem>

#include "common/error.hpp"

namespace st {

static_assert(sizeof(Rgb8) == 3, "Rgb8 rows are handed to libpng as packed RGB bytes");

namespace {

// Writes `width` x `height` pixels of `format` (channels bytes each) to path + ".tmp" and
// renames it into place, so a failed write never leaves a partial PNG under `path`.
void write_png_file(const std::string& path, uint32_t width, uint32_t height, uint32_t format, uint32_t channels,
                    const void* data) {
  png_image image;
  std::memset(&image, 0, sizeof image);
  image.version = PNG_IMAGE_VERSION;
  image.width = width;
  image.height = height;
  image.format = format;
  const std::string tmp = path + ".tmp";
  if (!png_image_write_to_file(&image, tmp.c_str(), 0, data, int32_t(width * channels), nullptr)) {
    std::string msg = image.message;
    png_image_free(&image);
    std::error_code ec;
    std::filesystem::remove(tmp, ec);
    throw Error(path + ": writing the PNG failed: " + msg);
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::filesystem::remove(tmp, ec);
    throw Error(path + ": cannot rename the finished PNG into place: " + ec.message());
  }
}

}  // namespace

void write_png(const std::string& path, uint32_t width, uint32_t height,
               const std::vector<Rgb8>& pixels) {
  if (width == 0 || height == 0 || width > (1u << 20) || height > (1u << 20))
    throw Error(path + ": PNG size " + std::to_string(width) + "x" + std::to_string(height) +
                " is empty or too large");
  if (pixels.size() != size_t(width) * height)
    throw Error(path + ": PNG pixel count does not match " + std::to_string(width) + "x" +
                std::to_string(height));
  write_png_file(path, width, height, PNG_FORMAT_RGB, 3, pixels.data());
}

std::vector<Rgb8> read_png(const std::string& path, uint32_t& width, uint32_t& height) {
  png_image image;
  std::memset(&image, 0, sizeof image);
  image.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_file(&image, path.c_str()))
    throw FormatError(path + ": cannot read the PNG: " + image.message);
  if (image.width == 0 || image.height == 0 || image.width > (1u << 16) || image.height > (1u << 16)) {
    png_image_free(&image);
    throw FormatError(path + ": PNG size is empty or larger than 65536 a side");
  }
  image.format = PNG_FORMAT_RGB;
  std::vector<Rgb8> pixels(size_t(image.width) * image.height);
  if (!png_image_finish_read(&image, nullptr, pixels.data(), int32_t(image.width) * 3, nullptr)) {
    std::string msg = image.message;
    png_image_free(&image);
    throw FormatError(path + ": cannot decode the PNG: " + msg);
  }
  width = image.width;
  height = image.height;
  return pixels;
}

namespace {

// Finishes a png_image whose header was read: decodes it as grey + alpha.
PngPlanes finish_planes(png_image& image, const std::string& name, uint64_t max_texels) {
  if (image.width == 0 || image.height == 0 || uint64_t(image.width) * image.height > max_texels) {
    const std::string size = std::to_string(image.width) + "x" + std::to_string(image.height);
    png_image_free(&image);
    throw FormatError(name + ": PNG of " + size + " texels is empty or larger than " +
                      std::to_string(max_texels) + " texels");
  }
  PngPlanes out;
  out.width = image.width;
  out.height = image.height;
  out.has_alpha = (image.format & PNG_FORMAT_FLAG_ALPHA) != 0;
  image.format = PNG_FORMAT_GA;
  std::vector<uint8_t> ga(size_t(image.width) * image.height * 2);
  if (!png_image_finish_read(&image, nullptr, ga.data(), int32_t(image.width) * 2, nullptr)) {
    std::string msg = image.message;
    png_image_free(&image);
    throw FormatError(name + ": cannot decode the PNG: " + msg);
  }
  const size_t n = size_t(out.width) * out.height;
  out.grey.resize(n);
  out.alpha.resize(n);
  for (size_t i = 0; i < n; ++i) out.grey[i] = ga[2 * i], out.alpha[i] = ga[2 * i + 1];
  return out;
}

}  // namespace

PngPlanes read_png_planes(const std::string& path, uint64_t max_texels) {
  png_image image;
  std::memset(&image, 0, sizeof image);
  image.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_file(&image, path.c_str()))
    throw FormatError(path + ": cannot read the PNG: " + image.message);
  return finish_planes(image, path, max_texels);
}

PngPlanes read_png_planes(const void* data, size_t size, const std::string& name,
                          uint64_t max_texels) {
  png_image image;
  std::memset(&image, 0, sizeof image);
  image.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_memory(&image, data, size))
    throw FormatError(name + ": cannot read the PNG: " + image.message);
  return finish_planes(image, name, max_texels);
}

void write_png_grey_alpha(const std::string& path, uint32_t width, uint32_t height,
                          const std::vector<uint8_t>& ga) {
  if (width == 0 || height == 0 || width > (1u << 20) || height > (1u << 20) ||
      ga.size() != size_t(width) * height * 2)
    throw Error(path + ": grey + alpha PNG data does not match " + std::to_string(width) + "x" +
                std::to_string(height));
  write_png_file(path, width, height, PNG_FORMAT_GA, 2, ga.data());
}

std::vector<Rgb8> depth_preview(const IntervalTile& tile, uint32_t max_side, uint32_t& width,
                                uint32_t& height) {
  if (tile.width == 0 || tile.height == 0 || max_side == 0)
    throw Error("depth preview: empty tile or zero preview size");
  const uint32_t side = std::max(tile.width, tile.height);
  const uint32_t step = (side + max_side - 1) / max_side;
  width = (tile.width + step - 1) / step;
  height = (tile.height + step - 1) / step;
  float near = 2, far = -1;
  for (uint32_t j = 0; j < tile.height; j += step)
    for (uint32_t i = 0; i < tile.width; i += step) {
      const Interval& iv = tile.at(i, j);
      if (iv.lo == kLitDepth && iv.hi == kLitDepth) continue;
      near = std::min(near, iv.lo), far = std::max(far, iv.lo);
    }
  const double range = far > near ? double(far) - near : 1.0;
  std::vector<Rgb8> px(size_t(width) * height);
  for (uint32_t y = 0; y < height; ++y)
    for (uint32_t x = 0; x < width; ++x) {
      const Interval& iv = tile.at(x * step, y * step);
      Rgb8& p = px[size_t(y) * width + x];
      if (iv.lo == kLitDepth && iv.hi == kLitDepth) {
        p = kPreviewLitColour;
        continue;
      }
      // Nearest hit 250, farthest 40: grey levels never collide with the lit colour.
      const double f = (double(iv.lo) - near) / range;
      const auto g = uint8_t(std::clamp(250.0 - 210.0 * f, 40.0, 250.0));
      p = {g, g, g};
    }
  return px;
}

void write_depth_preview_png(const std::string& path, const IntervalTile& tile,
                             uint32_t max_side) {
  uint32_t w = 0, h = 0;
  auto px = depth_preview(tile, max_side, w, h);
  write_png(path, w, h, px);
}

}  // namespace st
