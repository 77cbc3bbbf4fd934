#include "scene/scene_gltf_check.hpp"

#include <assimp/scene.h>

#include <cstring>
#include <map>
#include <nlohmann/json.hpp>
#include <string_view>

#include "common/error.hpp"

namespace st {
namespace {

// The JSON text of a glTF file, or empty if the bytes are not glTF-looking. GLB 2 layout
// (glTF 2.0 spec, "Binary glTF Layout"): 12-byte header "glTF", version, length; then the
// first chunk: u32 length, u32 type "JSON", its bytes.
std::string_view json_text(const std::vector<uint8_t>& b, const std::string& path) {
  const char* p = reinterpret_cast<const char*>(b.data());
  if (b.size() >= 4 && std::memcmp(p, "glTF", 4) == 0) {
    if (b.size() < 20) throw Error(path + ": binary glTF shorter than its 20-byte header");
    uint32_t len = 0;
    std::memcpy(&len, p + 12, 4);
    if (std::memcmp(p + 16, "JSON", 4) != 0) return {};  // glTF 1 binary: assimp decides
    if (len > b.size() - 20) throw Error(path + ": binary glTF JSON chunk of " + std::to_string(len) +
                                         " bytes runs past the file");
    return {p + 20, len};
  }
  size_t i = b.size() >= 3 && b[0] == 0xEF && b[1] == 0xBB && b[2] == 0xBF ? 3 : 0;  // UTF-8 BOM
  while (i < b.size() && (b[i] == ' ' || b[i] == '\t' || b[i] == '\r' || b[i] == '\n')) ++i;
  if (i >= b.size() || b[i] != '{') return {};
  return {p, b.size()};
}

void check_json_nesting(std::string_view s, const std::string& path) {
  uint32_t depth = 0;
  bool in_string = false;
  for (size_t i = 0; i < s.size(); ++i) {
    const char c = s[i];
    if (in_string) {
      if (c == '\\') ++i;
      else if (c == '"') in_string = false;
    } else if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      if (++depth > kMaxJsonNesting)
        throw Error(path + ": glTF JSON nests deeper than " + std::to_string(kMaxJsonNesting) + " levels at byte " +
                    std::to_string(i));
    } else if ((c == ']' || c == '}') && depth > 0) {
      --depth;
    }
  }
}

}  // namespace

void check_gltf_structure(const std::vector<uint8_t>& bytes, const std::string& path, uint64_t memory_bytes) {
  const std::string_view text = json_text(bytes, path);
  if (text.empty()) return;
  check_json_nesting(text, path);
  const nlohmann::json j = nlohmann::json::parse(text.begin(), text.end(), nullptr, false);
  if (j.is_discarded() || !j.is_object()) return;  // not JSON: assimp reports it
  const auto nodes_it = j.find("nodes");
  if (nodes_it == j.end()) return;
  const nlohmann::json& nodes = *nodes_it;
  if (memory_bytes > 0 && (nodes.is_array() || nodes.is_object()) && nodes.size() > memory_bytes / sizeof(aiNode))
    throw Error(path + ": glTF file has " + std::to_string(nodes.size()) + " nodes; assimp spends at least " +
                std::to_string(sizeof(aiNode)) + " bytes on each, more than the reader's limit of " +
                std::to_string(memory_bytes >> 20) + " MiB (raise it with --scene-limits memory=MIB)");
  // Node ids: glTF 2 indexes an array, glTF 1 names the members of an object.
  std::vector<std::string> names;
  std::map<std::string, size_t> by_name;
  std::vector<const nlohmann::json*> children;
  if (nodes.is_array()) {
    for (size_t i = 0; i < nodes.size(); ++i) {
      names.push_back(std::to_string(i));
      children.push_back(nodes[i].is_object() && nodes[i].contains("children") ? &nodes[i]["children"] : nullptr);
    }
  } else if (nodes.is_object()) {
    for (auto it = nodes.begin(); it != nodes.end(); ++it) {
      by_name[it.key()] = names.size();
      names.push_back(it.key());
      children.push_back(it->is_object() && it->contains("children") ? &(*it)["children"] : nullptr);
    }
  } else {
    return;
  }
  const size_t n = names.size();
  std::vector<std::vector<size_t>> kids(n);
  std::vector<uint32_t> parents(n, 0);
  for (size_t i = 0; i < n; ++i) {
    if (!children[i] || !children[i]->is_array()) continue;
    for (const auto& c : *children[i]) {
      size_t k = n;
      if (c.is_number_unsigned()) {
        if (c.get<uint64_t>() < n) k = size_t(c.get<uint64_t>());
      } else if (c.is_string()) {
        auto it = by_name.find(c.get<std::string>());
        if (it != by_name.end()) k = it->second;
      }
      if (k == n) throw Error(path + ": glTF node " + names[i] + " has a child that is not a node");
      if (++parents[k] > 1) throw Error(path + ": glTF node " + names[k] + " is the child of two nodes (a node may have one parent)");
      kids[i].push_back(k);
    }
  }
  // Depth of every tree, iteratively from the roots; nodes left unreached lie on a cycle.
  std::vector<uint32_t> depth(n, 0);
  std::vector<size_t> todo;
  size_t reached = 0;
  for (size_t i = 0; i < n; ++i)
    if (parents[i] == 0) depth[i] = 1, todo.push_back(i);
  while (!todo.empty()) {
    const size_t i = todo.back();
    todo.pop_back();
    ++reached;
    if (depth[i] > kMaxGltfNodeDepth)
      throw Error(path + ": glTF nodes nest deeper than " + std::to_string(kMaxGltfNodeDepth) + " levels (node " +
                  names[i] + ")");
    for (size_t k : kids[i]) depth[k] = depth[i] + 1, todo.push_back(k);
  }
  if (reached != n) throw Error(path + ": glTF node hierarchy has a cycle (" + std::to_string(n - reached) + " nodes on it)");
}

}  // namespace st
