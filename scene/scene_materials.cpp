// Partial occluders from a scene file's materials: see scene_materials.hpp.
#include "scene/scene_materials.hpp"

#include <assimp/GltfMaterial.h>
#include <assimp/material.h>
#include <assimp/scene.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "common/error.hpp"
#include "image/png_io.hpp"

namespace st {
namespace {

// Which plane of an image is the alpha that is tested.
enum class Plane { alpha, alpha_else_grey };

struct TextureRef {
  std::string path;  // as the material names it
  unsigned uv_channel = 0;
};

bool texture_of(const aiMaterial& m, aiTextureType type, TextureRef& out) {
  if (m.GetTextureCount(type) == 0) return false;
  aiString path;
  if (m.GetTexture(type, 0, &path) != AI_SUCCESS || path.length == 0) return false;
  out.path = path.C_Str();
  int channel = 0;
  if (m.Get(AI_MATKEY_UVWSRC(type, 0), channel) == AI_SUCCESS && channel >= 0) out.uv_channel = unsigned(channel);
  return true;
}

// A name for an image format we do not read, from its first bytes, else its extension.
std::string format_name(const uint8_t* head, size_t n, const std::string& path) {
  auto starts = [&](const char* magic, size_t len, size_t at = 0) {
    return n >= at + len && std::memcmp(head + at, magic, len) == 0;
  };
  if (starts("\xFF\xD8\xFF", 3)) return "JPEG";
  if (starts("DDS ", 4)) return "DDS";
  if (starts("\xABKTX", 4)) return "KTX";
  if (starts("BM", 2)) return "BMP";
  if (starts("GIF8", 4)) return "GIF";
  if (starts("RIFF", 4) && starts("WEBP", 4, 8)) return "WebP";
  if (starts("II*\0", 4) || starts("MM\0*", 4)) return "TIFF";
  if (starts("\x76\x2F\x31\x01", 4)) return "OpenEXR";
  if (starts("#?RADIANCE", 10)) return "Radiance HDR";
  if (starts("8BPS", 4)) return "PSD";
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = char(std::toupper(static_cast<unsigned char>(c)));
  if (!ext.empty() && ext[0] == '.') ext.erase(0, 1);
  return ext.empty() ? "an unknown format" : ext + " (by its extension)";
}

bool is_png(const uint8_t* head, size_t n) {
  return n >= 8 && std::memcmp(head, "\x89PNG\r\n\x1a\n", 8) == 0;
}

// A PNG's size from its IHDR chunk (PNG spec 11.2.2: width and height big-endian at
// bytes 16 and 20), 0 when the bytes do not hold one (libpng then says what is wrong).
uint64_t png_texels(const uint8_t* head, size_t n) {
  if (n < 24 || std::memcmp(head + 12, "IHDR", 4) != 0) return 0;
  auto be = [&](size_t at) {
    return uint32_t(head[at]) << 24 | uint32_t(head[at + 1]) << 16 | uint32_t(head[at + 2]) << 8 | head[at + 3];
  };
  return uint64_t(be(16)) * be(20);
}

}  // namespace

FileMaterials::FileMaterials(const aiScene& scene, const std::string& model_path, uint64_t max_texels)
    : as_(scene),
      model_path_(model_path),
      done_(scene.mNumMaterials),
      read_(scene.mNumMaterials, false),
      max_texels_(max_texels) {}

const MaterialPartial& FileMaterials::get(unsigned index, Scene& scene) {
  static const MaterialPartial kOpaque{};
  if (index >= as_.mNumMaterials || !as_.mMaterials || !as_.mMaterials[index]) return kOpaque;
  if (read_[index]) return done_[index];
  const aiMaterial& m = *as_.mMaterials[index];
  aiString mname;
  const std::string name =
      m.Get(AI_MATKEY_NAME, mname) == AI_SUCCESS && mname.length ? mname.C_Str() : "#" + std::to_string(index);
  const std::string where = model_path_ + ": material '" + name + "'";
  auto real = [&](const char* key, unsigned type, unsigned idx, float& v) {
    if (m.Get(key, type, idx, v) != AI_SUCCESS) return false;
    if (!std::isfinite(v)) throw Error(where + ": " + key + " is not finite");
    return true;
  };

  MaterialPartial out;
  float cutoff = 0.5f, factor = 1.0f;  // alpha test: cutoff, and the factor alpha scales by
  Plane plane = Plane::alpha_else_grey;
  TextureRef tex;
  bool textured = false;
  aiString mode;
  if (m.Get(AI_MATKEY_GLTF_ALPHAMODE, mode) == AI_SUCCESS) {
    const std::string am = mode.C_Str();
    float f = 1;
    real(AI_MATKEY_OPACITY, f);  // assimp's glTF importer: baseColorFactor.a
    f = std::clamp(f, 0.0f, 1.0f);
    if (am == "MASK" || am == "BLEND") {
      textured = texture_of(m, aiTextureType_BASE_COLOR, tex) || texture_of(m, aiTextureType_DIFFUSE, tex);
      plane = Plane::alpha;
    }
    if (am == "MASK") {
      float c = 0.5f;
      if (real(AI_MATKEY_GLTF_ALPHACUTOFF, c)) cutoff = std::clamp(c, 0.0f, 1.0f);
      if (textured) factor = f;  // texel alpha x factor against the cutoff
      else if (f < cutoff) out.transmit = {1, 1, 1};
    } else if (am == "BLEND") {
      out.transmit = {1 - f, 1 - f, 1 - f};
    } else if (am != "OPAQUE") {
      throw Error(where + ": unknown glTF alphaMode '" + am + "' (OPAQUE, MASK or BLEND)");
    }
  } else {
    float o = 1, t = 0;
    if (!real(AI_MATKEY_OPACITY, o) && real(AI_MATKEY_TRANSPARENCYFACTOR, t)) o = 1 - t;
    o = std::clamp(o, 0.0f, 1.0f);
    Rgb tint{1, 1, 1};
    aiColor3D c;
    if (m.Get(AI_MATKEY_COLOR_TRANSPARENT, c) == AI_SUCCESS) {
      if (!std::isfinite(c.r) || !std::isfinite(c.g) || !std::isfinite(c.b))
        throw Error(where + ": transparent colour is not finite");
      const float most = std::max({c.r, c.g, c.b});
      if (most > 0) tint = {std::max(c.r, 0.0f) / most, std::max(c.g, 0.0f) / most, std::max(c.b, 0.0f) / most};
    }
    if (o < 1) out.transmit = {(1 - o) * tint[0], (1 - o) * tint[1], (1 - o) * tint[2]};
    textured = texture_of(m, aiTextureType_OPACITY, tex);
  }

  if (textured) {
    out.uv_channel = tex.uv_channel;
    std::string key;
    std::vector<uint8_t> head;
    PngPlanes img;
    std::string label;      // what errors call the texture
    std::string file_path;  // an image file's path (not embedded)
    std::string ref = tex.path;
    std::replace(ref.begin(), ref.end(), '\\', '/');
    const aiTexture* embedded = as_.GetEmbeddedTexture(tex.path.c_str());
    if (embedded) {
      label = "embedded texture '" + tex.path + "'";
      key = "embedded:" + tex.path;
    } else {
      namespace fs = std::filesystem;
      const fs::path p = fs::path(ref).is_absolute() ? fs::path(ref) : fs::path(model_path_).parent_path() / ref;
      file_path = p.string();
      label = "texture '" + file_path + "'";
      key = "file:" + p.lexically_normal().string();
    }
    key += plane == Plane::alpha ? "|a|" : "|ag|";
    key += std::to_string(factor) + "|" + std::to_string(cutoff);
    if (auto it = textures_.find(key); it != textures_.end()) {
      out.alpha_texture = it->second;
    } else {
      // Counted against the scene's budget from the image's header, before decoding it.
      auto budget = [&](uint64_t texels) {
        if (texels > max_texels_ - std::min(texels_, max_texels_))
          throw Error(label + " has " + std::to_string(texels) + " texels, which takes the scene's alpha textures past " +
                      std::to_string(max_texels_) + " texels, the limit (raise it with --scene-limits texels=N)");
      };
      try {
        if (embedded && embedded->mHeight != 0) {  // uncompressed ARGB8888 texels
          const uint64_t n = uint64_t(embedded->mWidth) * embedded->mHeight;
          budget(n);
          if (n > kMaxAlphaTexels) throw FormatError(label + " is larger than 8192^2 texels");
          img.width = embedded->mWidth, img.height = embedded->mHeight;
          img.has_alpha = true;
          img.alpha.resize(n), img.grey.resize(n);
          for (uint64_t i = 0; i < n; ++i) {
            const aiTexel& t = embedded->pcData[i];
            img.alpha[i] = t.a;
            img.grey[i] = uint8_t((299 * t.r + 587 * t.g + 114 * t.b + 500) / 1000);
          }
        } else if (embedded) {  // compressed bytes: mWidth of them
          const auto* bytes = reinterpret_cast<const uint8_t*>(embedded->pcData);
          if (!is_png(bytes, embedded->mWidth))
            throw Error(label + " is " + format_name(bytes, embedded->mWidth, "." + std::string(embedded->achFormatHint)) +
                        "; only PNG textures are read (re-export it as PNG)");
          budget(png_texels(bytes, embedded->mWidth));
          img = read_png_planes(bytes, embedded->mWidth, label, kMaxAlphaTexels);
        } else {
          const std::string& path = file_path;
          std::ifstream f(path, std::ios::binary);
          if (!f) throw Error(label + " not found or unreadable");
          uint8_t buf[24] = {};
          f.read(reinterpret_cast<char*>(buf), sizeof buf);
          const size_t got = size_t(f.gcount());
          if (!is_png(buf, got))
            throw Error(label + " is " + format_name(buf, got, path) +
                        "; only PNG textures are read (convert it to PNG)");
          budget(png_texels(buf, got));
          img = read_png_planes(path, kMaxAlphaTexels);
        }
        texels_ += uint64_t(img.width) * img.height;
      } catch (const Error& e) {
        throw Error(where + ": " + e.what());
      }
      AlphaTexture at;
      at.name = label;
      at.width = img.width, at.height = img.height;
      at.cutoff = cutoff;
      const std::vector<uint8_t>& src =
          plane == Plane::alpha || img.has_alpha ? img.alpha : img.grey;
      at.alpha.resize(src.size());
      for (uint32_t y = 0; y < img.height; ++y)  // row 0 of an image is its top, v = 1
        for (uint32_t x = 0; x < img.width; ++x) {
          const uint8_t a = src[size_t(img.height - 1 - y) * img.width + x];
          at.alpha[size_t(y) * img.width + x] = factor == 1.0f ? a : uint8_t(std::lround(a * factor));
        }
      at.validate();
      out.alpha_texture = int32_t(scene.alpha_textures.size());
      scene.alpha_textures.push_back(std::move(at));
      textures_.emplace(key, out.alpha_texture);
    }
  }
  read_[index] = true;
  done_[index] = out;
  return done_[index];
}

}  // namespace st
