// Partial occluders from a scene file's materials (assimp 5.2): what a material makes of
// the light crossing its mesh (partial.hpp; DSM 2000 §3.2 surface transmittance, §5.2
// colour). Only the shadow-relevant part of a material is read.
//
// glTF (a material carrying $mat.gltf.alphaMode):
//   OPAQUE  opaque, whatever the base colour's alpha (the glTF rule).
//   MASK    alpha = baseColorFactor.a x the base colour texture's alpha (when there is
//           one); the surface is solid (opaque) where alpha >= alphaCutoff (default 0.5)
//           and lets all light through elsewhere. Without a texture the whole mesh is
//           opaque or fully clear.
//   BLEND   transmit = 1 - baseColorFactor.a (grey); with a base colour texture, alpha-
//           tested at 0.5 as well (a blended texture's fractional alpha is thresholded:
//           the jittered samples of a texel average the coverage, not the alpha).
// Other formats (OBJ/MTL, FBX, COLLADA, ...):
//   opacity o = AI_MATKEY_OPACITY (MTL `d`, or 1 - `Tr`), else 1 - AI_MATKEY_
//   TRANSPARENCYFACTOR when only that is given, else 1; clamped to [0, 1].
//   tint = AI_MATKEY_COLOR_TRANSPARENT (MTL `Tf`) divided by its largest channel; absent
//   or black: white (FBX and COLLADA exporters write the transparency itself there, or
//   black by default; dividing keeps only its hue, so both readings agree on grey).
//   transmit = (1 - o) x tint, per channel. o = 1: opaque (the mesh stays in the opaque
//   map exactly as a file without materials).
//   An opacity map (aiTextureType_OPACITY, MTL `map_d`) alpha-tests the mesh at 0.5: on
//   its alpha channel when the image has one, else on its grey level (white = solid);
//   where solid, the transmit above applies (0 when o = 1: an alpha-tested opaque card).
//   A diffuse texture's alpha is not read for these formats (only glTF says it is alpha).
//
// Textures: PNG files (any bit depth and colour type) named relative to the model file's
// folder ('\' read as '/'), PNG embedded in the file (glb, data URIs), and assimp's
// uncompressed embedded textures. Anything else (JPEG, TGA, DDS, KTX, ...; a missing
// file; a texture over kMaxAlphaTexels) is an st::Error of one line naming the scene,
// the material, the texture and its format: a shadow is never silently dropped. Rows are
// flipped on load (AlphaTexture row 0 is v = 0; assimp's v = 0 is an image's bottom row,
// as in OpenGL: its glTF importer flips v). Texture wrap modes are ignored (repeat).
// Texture coordinates come from the channel the material names (AI_MATKEY_UVWSRC, else
// 0); an alpha-tested mesh without them is an error.
#pragma once
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "scene/scene.hpp"

struct aiScene;

namespace st {

inline constexpr uint64_t kMaxAlphaTexels = uint64_t(1) << 26;  // 8192^2

struct MaterialPartial {
  Rgb transmit{0, 0, 0};
  int32_t alpha_texture = -1;  // index into Scene::alpha_textures
  unsigned uv_channel = 0;     // the mesh's texture coordinates to alpha-test with
};

// Reads each material of an imported scene once, adding the alpha textures it needs to
// the scene (one AlphaTexture per distinct image, plane, factor and cutoff).
class FileMaterials {
 public:
  // `max_texels`: the texels all alpha textures of the scene may hold together, checked
  // from each image's header before it is decoded (SceneLimits::max_texels).
  FileMaterials(const aiScene& scene, const std::string& model_path, uint64_t max_texels);
  // Throws st::Error (one line) for a material or texture that cannot be read.
  const MaterialPartial& get(unsigned material_index, Scene& scene);

 private:
  const aiScene& as_;
  std::string model_path_;
  std::vector<MaterialPartial> done_;
  std::vector<bool> read_;
  std::map<std::string, int32_t> textures_;  // dedupe key -> index
  uint64_t max_texels_ = 0, texels_ = 0;      // the budget, and what the textures hold
};

}  // namespace st
