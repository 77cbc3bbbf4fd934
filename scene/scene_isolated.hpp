// Reading a scene file in a child process, so that what a hostile file does to a reader we
// do not control (assimp allocating from header counts, recursing past any stack, crashing)
// costs at most the limits of SceneLimits and ends in one line of error. The child sends
// the finished scene back through a pipe in the bounded format drawn in scene_isolated.cpp;
// the parent checks every count against the limits before it allocates, and the scene's
// structure (indices in range, meshes partitioning the triangles) after.
#pragma once
#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "scene/scene.hpp"
#include "scene/scene_limits.hpp"

namespace st {

// Runs `read` in a forked child and returns the scene it built. In the child: no core
// dumps, an address-space limit of its size at the fork + limits.memory_bytes + the
// 256 MiB import stack's reservation (RLIMIT_AS; under AddressSanitizer, which reserves
// terabytes, the parent instead kills a child whose resident memory grows past
// 2 x memory_bytes + 256 MiB), and `read` runs on a thread with that 256 MiB stack. The parent kills the child
// after limits.seconds. Throws st::Error naming `path` for: an error thrown by `read`
// (its own message), memory exhausted, the deadline passed, a crash (the signal named), an
// answer that breaks the format or the limits. Without limits.isolate, `read` runs on a
// 256 MiB-stack thread of this process instead.
Scene read_scene_isolated(const std::string& path, const SceneLimits& limits, const std::function<Scene()>& read);

// The answer format, on any byte stream (exposed for tests: truncation, hostile counts).
struct SceneSink {
  virtual ~SceneSink() = default;
  virtual void put(const void* data, size_t bytes) = 0;  // throws st::Error when it cannot
};
struct SceneSource {
  virtual ~SceneSource() = default;
  virtual void get(void* data, size_t bytes) = 0;  // exactly `bytes`, else throws st::Error
};
void write_scene_answer(SceneSink& out, const Scene& scene);
void write_error_answer(SceneSink& out, const std::string& message);
// The scene of an answer (named `path`), or the st::Error it carries. Every count is
// checked against `limits` before anything is allocated for it; the decoded scene's
// structure is checked too. Throws st::Error naming `path` for a malformed answer.
Scene read_scene_answer(SceneSource& in, const std::string& path, const SceneLimits& limits);

// The most bytes an error message or a name may take in an answer.
inline constexpr uint32_t kMaxAnswerText = 4096;

}  // namespace st
