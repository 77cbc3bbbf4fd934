// Structural checks on glTF files before assimp sees them. assimp 5.2.5 imports glTF node
// hierarchies (and parses JSON) by recursion, so a small file nesting 20,000 nodes
// overflows the stack; a node listed as the child of two parents is imported once per
// path (2^n copies for n such levels), and a cycle never ends.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

namespace st {

// Nesting bounds: far above real files (scene graphs of skinned characters are < 100
// deep; glTF JSON nests < 10 deep), far below what assimp's recursion survives on a
// 8 MiB stack.
inline constexpr uint32_t kMaxGltfNodeDepth = 1024;
inline constexpr uint32_t kMaxJsonNesting = 256;

// If `bytes` look like glTF (a binary .glb: magic "glTF"; JSON: first non-blank byte '{'),
// checks its JSON: brackets nested at most kMaxJsonNesting deep, and the node graph
// ("nodes"[i]."children", glTF 2 indices or glTF 1 ids) a forest (no node with two
// parents, no cycle, children that exist) at most kMaxGltfNodeDepth deep. Throws st::Error
// naming `path` and what is wrong; returns quietly for anything else (other formats, or
// JSON that assimp will refuse by itself). With `memory_bytes` (the reader's limit,
// scene_limits.hpp; 0: none), a file with more nodes than that many bytes hold at one
// aiNode each (the least assimp spends on a node: its 1 KiB name buffer and more) is
// refused before the node graph is walked: 10^6 nodes in 59 MB took assimp 2.35 GiB.
void check_gltf_structure(const std::vector<uint8_t>& bytes, const std::string& path, uint64_t memory_bytes = 0);

}  // namespace st
