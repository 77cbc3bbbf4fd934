// Scene files read in a child process under memory and time limits: see scene_isolated.hpp.
//
// Answer format (child -> parent through a pipe; both sides are the same build on the same
// machine, so numbers travel in host byte order; every size is checked by the reader):
//   offset  size  field
//   0       8     magic "STSCANS2" (the version is its last byte)
//   8       4     kind: 0 scene, 1 error
//   error:  12 4 message length n (<= kMaxAnswerText), then n bytes of message
//   scene:  12 8 vertices V          20 8 triangles T         28 8 meshes M
//           36 8 triangle_uv U (0 or T)                       44 8 alpha textures A
//           52 8 stats.degenerate_dropped                     60 8 stats.meshes_flipped
//           68    V x 24  vertices (3 doubles)
//                 T x 12  triangles (3 u32)
//                 U x 24  triangle_uv (3 x 2 floats)
//                 M x     mesh: u32 name length + name, u32 first_triangle, u32
//                         triangle_count, u8 closed, 3 x f32 transmit, i32 alpha_texture
//                 A x     texture: u32 name length + name, u32 width, u32 height, f32
//                         cutoff, width x height alpha bytes
//                 u32 up axis (0 y, 1 z), u32 up reason length + reason (Scene::up, up_reason)
//                 u32 unit reason length + reason (Scene::unit_reason)
//           then 8 bytes "STSCEND3".
#include "scene/scene_isolated.hpp"

#include <fcntl.h>
#include <poll.h>
#include <pthread.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <exception>
#include <fstream>
#include <new>
#include <stdexcept>

#include "common/error.hpp"
#include "common/sanitizer.hpp"

namespace st {
namespace {

constexpr char kMagic[8] = {'S', 'T', 'S', 'C', 'A', 'N', 'S', '2'};
constexpr char kEndMagic[8] = {'S', 'T', 'S', 'C', 'E', 'N', 'D', '3'};
constexpr uint32_t kKindScene = 0, kKindError = 1;
// Stack of the thread a scene is imported on (reserved, touched only as deep as the
// reader recurses: assimp imports and frees node trees, and parses XML and JSON, by
// recursion).
constexpr size_t kImportStackBytes = size_t(256) << 20;


template <class T>
void put(SceneSink& out, const T& v) {
  out.put(&v, sizeof v);
}
template <class T>
T get(SceneSource& in) {
  T v;
  in.get(&v, sizeof v);
  return v;
}

void put_text(SceneSink& out, const std::string& s) {
  const uint32_t n = uint32_t(std::min<size_t>(s.size(), kMaxAnswerText));
  put(out, n);
  out.put(s.data(), n);
}

// Runs `fn` on a new thread with a stack of `bytes` and waits for it; `fn` must not throw.
void run_with_stack(size_t bytes, const std::function<void()>& fn) {
  pthread_attr_t attr;
  if (pthread_attr_init(&attr) != 0) {
    fn();
    return;
  }
  pthread_attr_setstacksize(&attr, bytes);
  pthread_t thread;
  auto trampoline = [](void* f) -> void* {
    (*static_cast<const std::function<void()>*>(f))();
    return nullptr;
  };
  const int rc = pthread_create(&thread, &attr, trampoline, const_cast<std::function<void()>*>(&fn));
  pthread_attr_destroy(&attr);
  if (rc != 0) {  // no thread (address space or thread limits): read on this one
    fn();
    return;
  }
  pthread_join(thread, nullptr);
}

std::string mib(uint64_t bytes) { return std::to_string(bytes >> 20) + " MiB"; }

std::string memory_message(const std::string& path, const SceneLimits& l) {
  if (!l.isolate || l.memory_bytes == 0) return path + ": out of memory reading it";
  return path + ": out of memory reading it: the reader's limit of " + mib(l.memory_bytes) +
         " was reached (raise it with --scene-limits memory=MIB)";
}

// `read` on a big-stack thread, its exceptions turned into an st::Error of one line.
Scene read_on_big_stack(const std::string& path, const SceneLimits& limits, const std::function<Scene()>& read) {
  Scene scene;
  std::exception_ptr failure;
  run_with_stack(kImportStackBytes, [&]() {
    try {
      scene = read();
    } catch (const Error&) {
      failure = std::current_exception();
    } catch (const std::bad_alloc&) {
      failure = std::make_exception_ptr(Error(memory_message(path, limits)));
    } catch (const std::length_error&) {
      failure = std::make_exception_ptr(Error(memory_message(path, limits)));
    } catch (const std::exception& e) {
      failure = std::make_exception_ptr(Error(path + ": cannot read it: " + e.what()));
    } catch (...) {
      failure = std::make_exception_ptr(Error(path + ": cannot read it (an unknown error)"));
    }
  });
  if (failure) std::rethrow_exception(failure);
  return scene;
}

struct FdSink final : SceneSink {
  int fd;
  explicit FdSink(int f) : fd(f) {}
  void put(const void* data, size_t bytes) override {
    auto* p = static_cast<const char*>(data);
    while (bytes > 0) {
      const ssize_t n = ::write(fd, p, std::min<size_t>(bytes, size_t(1) << 20));
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) ::_exit(3);  // the parent stopped listening: nothing left to tell it
      p += n, bytes -= size_t(n);
    }
  }
};

uint64_t statm_field(pid_t pid, int field) {  // pages of /proc/PID/statm's field (0: size, 1: resident)
  std::ifstream f("/proc/" + std::to_string(pid) + "/statm");
  uint64_t v = 0;
  for (int i = 0; i <= field; ++i)
    if (!(f >> v)) return 0;
  return v * uint64_t(::sysconf(_SC_PAGESIZE));
}

// What the child's terminate handler says: assimp lets std::bad_alloc escape through
// noexcept code (seen with 100,000 glTF nodes under a 64 MiB limit), which calls
// std::terminate. The message is made before reading, so saying it allocates nothing.
int g_child_fd = -1;
const std::string* g_child_oom_message = nullptr;

[[noreturn]] void child_terminate() {
  bool memory = false;
  if (const std::exception_ptr e = std::current_exception()) {
    try {
      std::rethrow_exception(e);
    } catch (const std::bad_alloc&) {
      memory = true;
    } catch (const std::length_error&) {
      memory = true;
    } catch (...) {
    }
  }
  if (memory && g_child_fd >= 0 && g_child_oom_message) {
    FdSink out(g_child_fd);
    write_error_answer(out, *g_child_oom_message);
    ::_exit(0);
  }
  std::abort();
}

[[noreturn]] void child_main(int fd, const std::string& path, const SceneLimits& limits,
                             const std::function<Scene()>& read) {
  static const std::string oom = memory_message(path, limits);
  g_child_oom_message = &oom;
  g_child_fd = fd;
  std::set_terminate(child_terminate);
  const rlimit no_core{0, 0};  // a crash here is reported by the parent, not dumped
  ::setrlimit(RLIMIT_CORE, &no_core);
  if (limits.memory_bytes > 0 && !kAddressSanitizer) {
    const uint64_t now = statm_field(::getpid(), 0);
    if (now > 0) {
      // The import stack's reservation comes on top: it is touched only as deep as the
      // reader recurses (nesting is checked before assimp for glTF and XML). Counted within
      // the limit, it left a legitimate 2,000,000-triangle OBJ (794 MiB resident) short.
      const uint64_t cap = now + limits.memory_bytes + kImportStackBytes;
      const rlimit r{rlim_t(cap), rlim_t(cap)};
      ::setrlimit(RLIMIT_AS, &r);
    }
  }
  FdSink out(fd);
  try {
    const Scene scene = read_on_big_stack(path, limits, read);
    write_scene_answer(out, scene);
  } catch (const Error& e) {
    write_error_answer(out, e.what());
  } catch (...) {  // out of memory while writing the answer
    write_error_answer(out, memory_message(path, limits));
  }
  ::_exit(0);
}

// Reads the pipe with the deadline, watching the child's memory under ASan.
struct PipeSource final : SceneSource {
  int fd;
  pid_t pid;
  std::chrono::steady_clock::time_point deadline;
  bool has_deadline;
  uint64_t rss_cap;  // 0: not watched
  std::string stop_reason;  // why the parent killed the child
  void get(void* data, size_t bytes) override {
    auto* p = static_cast<char*>(data);
    while (bytes > 0) {
      pollfd pfd{fd, POLLIN, 0};
      const int r = ::poll(&pfd, 1, 20);
      if (r < 0 && errno != EINTR) throw Error("poll failed");
      if (has_deadline && std::chrono::steady_clock::now() > deadline) {
        stop_reason = "deadline";
        throw Error("deadline");
      }
      if (rss_cap && statm_field(pid, 1) > rss_cap) {
        stop_reason = "memory";
        throw Error("memory");
      }
      if (r <= 0) continue;
      const ssize_t n = ::read(fd, p, bytes);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) throw Error("end of answer");
      p += n, bytes -= size_t(n);
    }
  }
};

// Kills and reaps the child unless it was reaped already.
struct Child {
  pid_t pid = -1;
  int status = 0;
  rusage usage{};
  bool reaped = false;
  void reap(bool kill_first) {
    if (reaped || pid <= 0) return;
    if (kill_first) ::kill(pid, SIGKILL);
    while (::wait4(pid, &status, 0, &usage) < 0 && errno == EINTR) {
    }
    reaped = true;
  }
  ~Child() { reap(true); }
};

std::string signal_name(int sig) {
  switch (sig) {
    case SIGSEGV: return "SIGSEGV";
    case SIGBUS: return "SIGBUS";
    case SIGABRT: return "SIGABRT";
    case SIGFPE: return "SIGFPE";
    case SIGILL: return "SIGILL";
    case SIGKILL: return "SIGKILL";
    default: return "signal " + std::to_string(sig);
  }
}

void check_count(uint64_t n, uint64_t limit, const std::string& path, const char* what) {
  if (n > limit)
    throw Error(path + ": the reader's answer claims " + std::to_string(n) + " " + what + ", more than " +
                std::to_string(limit));
}

}  // namespace

SceneLimits parse_scene_limits(const std::string& text, SceneLimits l) {
  const std::string usage = "--scene-limits: expected none or KEY=VALUE[,...] with keys memory (MiB), seconds, "
                            "triangles, texels, isolate (0 or 1); got '" + text + "'";
  if (text.empty()) return l;
  if (text == "none") {
    l.memory_bytes = 0, l.seconds = 0, l.max_triangles = UINT32_MAX, l.max_texels = UINT64_MAX;
    return l;
  }
  size_t at = 0;
  while (at <= text.size()) {
    const size_t comma = std::min(text.find(',', at), text.size());
    const std::string item = text.substr(at, comma - at);
    const size_t eq = item.find('=');
    if (eq == std::string::npos) throw Error(usage);
    const std::string key = item.substr(0, eq), value = item.substr(eq + 1);
    if (value.empty() || value.size() > 19 || value.find_first_not_of("0123456789") != std::string::npos)
      throw Error("--scene-limits: " + key + " wants a non-negative integer, got '" + value + "'");
    const uint64_t v = std::stoull(value);
    if (key == "memory") {
      if (v > (uint64_t(1) << 40)) throw Error("--scene-limits: memory is in MiB, at most 2^40");
      l.memory_bytes = v << 20;
    } else if (key == "seconds") {
      l.seconds = double(v);
    } else if (key == "triangles") {
      if (v == 0 || v > UINT32_MAX) throw Error("--scene-limits: triangles must be in [1, 2^32-1]");
      l.max_triangles = v;
    } else if (key == "texels") {
      l.max_texels = v;
    } else if (key == "isolate") {
      if (v > 1) throw Error("--scene-limits: isolate is 0 or 1");
      l.isolate = v == 1;
    } else {
      throw Error(usage);
    }
    at = comma + 1;
  }
  return l;
}

void write_error_answer(SceneSink& out, const std::string& message) {
  out.put(kMagic, sizeof kMagic);
  put(out, kKindError);
  put_text(out, message);
}

void write_scene_answer(SceneSink& out, const Scene& s) {
  out.put(kMagic, sizeof kMagic);
  put(out, kKindScene);
  put<uint64_t>(out, s.vertices.size());
  put<uint64_t>(out, s.triangles.size());
  put<uint64_t>(out, s.meshes.size());
  put<uint64_t>(out, s.triangle_uv.size());
  put<uint64_t>(out, s.alpha_textures.size());
  put<uint64_t>(out, s.stats.degenerate_dropped);
  put<uint64_t>(out, s.stats.meshes_flipped);
  static_assert(sizeof(Vec3d) == 24 && sizeof(s.triangles[0]) == 12 && sizeof(s.triangle_uv[0]) == 24,
                "the answer format sends these arrays as they are in memory");
  out.put(s.vertices.data(), s.vertices.size() * sizeof(Vec3d));
  out.put(s.triangles.data(), s.triangles.size() * sizeof(s.triangles[0]));
  out.put(s.triangle_uv.data(), s.triangle_uv.size() * sizeof(s.triangle_uv[0]));
  for (const Mesh& m : s.meshes) {
    put_text(out, m.name);
    put(out, m.first_triangle);
    put(out, m.triangle_count);
    put<uint8_t>(out, m.closed ? 1 : 0);
    put(out, m.transmit);
    put(out, m.alpha_texture);
  }
  for (const AlphaTexture& t : s.alpha_textures) {
    put_text(out, t.name);
    put(out, t.width);
    put(out, t.height);
    put(out, t.cutoff);
    out.put(t.alpha.data(), t.alpha.size());
  }
  put<uint32_t>(out, s.up == UpAxis::z ? 1 : 0);
  put_text(out, s.up_reason);
  put_text(out, s.unit_reason);
  out.put(kEndMagic, sizeof kEndMagic);
}

Scene read_scene_answer(SceneSource& in, const std::string& path, const SceneLimits& limits) {
  auto text = [&](const char* what) {
    const uint32_t n = get<uint32_t>(in);
    if (n > kMaxAnswerText) throw Error(path + ": the reader's answer has a " + what + " of " + std::to_string(n) + " bytes");
    std::string s(n, '\0');
    in.get(s.data(), n);
    return s;
  };
  char magic[8];
  in.get(magic, sizeof magic);
  if (std::memcmp(magic, kMagic, sizeof magic) != 0) throw Error(path + ": the reader's answer has a bad magic");
  const uint32_t kind = get<uint32_t>(in);
  if (kind == kKindError) {
    std::string m = text("message");
    for (char& c : m)
      if (c == '\n' || c == '\r') c = ' ';
    throw Error(m);
  }
  if (kind != kKindScene) throw Error(path + ": the reader's answer has an unknown kind " + std::to_string(kind));
  const uint64_t max_tri = std::min<uint64_t>(limits.max_triangles, UINT32_MAX);
  Scene s;
  s.name = path;
  const uint64_t nv = get<uint64_t>(in), nt = get<uint64_t>(in), nm = get<uint64_t>(in), nu = get<uint64_t>(in),
                 na = get<uint64_t>(in);
  s.stats.degenerate_dropped = get<uint64_t>(in);
  s.stats.meshes_flipped = get<uint64_t>(in);
  check_count(nt, max_tri, path, "triangles");
  check_count(nv, std::min<uint64_t>(3 * max_tri, UINT32_MAX), path, "vertices");
  check_count(nm, max_tri + 1, path, "meshes");  // every mesh kept had a triangle before cleaning
  if (nu != 0 && nu != nt) throw Error(path + ": the reader's answer has " + std::to_string(nu) + " UV triangles for " +
                                       std::to_string(nt) + " triangles");
  check_count(na, nm, path, "alpha textures");
  s.vertices.resize(nv);
  in.get(s.vertices.data(), nv * sizeof(Vec3d));
  s.triangles.resize(nt);
  in.get(s.triangles.data(), nt * sizeof(s.triangles[0]));
  s.triangle_uv.resize(nu);
  in.get(s.triangle_uv.data(), nu * sizeof(s.triangle_uv[0]));
  s.meshes.resize(nm);
  uint64_t next = 0;
  for (Mesh& m : s.meshes) {
    m.name = text("mesh name");
    m.first_triangle = get<uint32_t>(in);
    m.triangle_count = get<uint32_t>(in);
    m.closed = get<uint8_t>(in) != 0;
    m.transmit = get<Rgb>(in);
    m.alpha_texture = get<int32_t>(in);
    if (m.first_triangle != next || m.triangle_count > nt - next)
      throw Error(path + ": the reader's answer has meshes that do not partition the triangles");
    next += m.triangle_count;
    if (m.alpha_texture < -1 || m.alpha_texture >= int64_t(na))
      throw Error(path + ": the reader's answer names a missing alpha texture");
    for (float f : m.transmit)
      if (!(f >= 0.0f && f <= 1.0f)) throw Error(path + ": the reader's answer has a transmittance outside [0, 1]");
  }
  if (next != nt) throw Error(path + ": the reader's answer has meshes that do not partition the triangles");
  uint64_t texels = 0;
  s.alpha_textures.resize(na);
  for (AlphaTexture& t : s.alpha_textures) {
    t.name = text("texture name");
    t.width = get<uint32_t>(in);
    t.height = get<uint32_t>(in);
    t.cutoff = get<float>(in);
    texels += uint64_t(t.width) * t.height;
    check_count(texels, limits.max_texels, path, "alpha texels");
    t.alpha.resize(size_t(t.width) * t.height);
    in.get(t.alpha.data(), t.alpha.size());
    t.validate();
  }
  const uint32_t up = get<uint32_t>(in);
  if (up > 1) throw Error(path + ": the reader's answer has an unknown up axis " + std::to_string(up));
  s.up = up == 1 ? UpAxis::z : UpAxis::y;
  s.up_reason = text("up reason");
  s.unit_reason = text("unit reason");
  in.get(magic, sizeof magic);
  if (std::memcmp(magic, kEndMagic, sizeof magic) != 0) throw Error(path + ": the reader's answer has a bad end");
  for (auto& tri : s.triangles)
    for (uint32_t i : tri)
      if (i >= nv) throw Error(path + ": the reader's answer has a triangle index past its vertices");
  for (auto& v : s.vertices)
    if (!is_finite(v)) throw Error(path + ": the reader's answer has a non-finite vertex");
  return s;
}

Scene read_scene_isolated(const std::string& path, const SceneLimits& limits, const std::function<Scene()>& read) {
  if (!limits.isolate) return read_on_big_stack(path, limits, read);
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0) throw Error(path + ": cannot start the reader: pipe: " + std::strerror(errno));
  const uint64_t rss_at_fork = statm_field(::getpid(), 1);
  std::fflush(nullptr);  // nothing buffered is written twice
  Child child;
  child.pid = ::fork();
  if (child.pid < 0) {
    const int e = errno;
    ::close(fds[0]), ::close(fds[1]);
    throw Error(path + ": cannot start the reader: fork: " + std::strerror(e));
  }
  if (child.pid == 0) {
    ::close(fds[0]);
    child_main(fds[1], path, limits, read);
  }
  ::close(fds[1]);
  struct CloseFd {
    int fd;
    ~CloseFd() { ::close(fd); }
  } close_read{fds[0]};
  PipeSource source;
  source.fd = fds[0];
  source.pid = child.pid;
  source.has_deadline = limits.seconds > 0;
  source.deadline = std::chrono::steady_clock::now() +
                    std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                        std::chrono::duration<double>(source.has_deadline ? limits.seconds : 0.0));
  source.rss_cap = kAddressSanitizer && limits.memory_bytes ? rss_at_fork + 2 * limits.memory_bytes + (uint64_t(256) << 20) : 0;
  std::string transport_failure;
  try {
    Scene scene = read_scene_answer(source, path, limits);
    child.reap(false);
    return scene;
  } catch (const Error& e) {
    if (source.stop_reason.empty() && std::string(e.what()) != "end of answer") {
      // The child's own error, or an answer the parent refused: either way it is final.
      child.reap(true);
      throw;
    }
  }
  // The pipe ended early or a limit stopped it: say why in terms of the child.
  if (source.stop_reason == "deadline") {
    child.reap(true);
    throw Error(path + ": reading it took longer than the reader's limit of " + std::to_string(int(limits.seconds)) +
                " s (raise it with --scene-limits seconds=S)");
  }
  if (source.stop_reason == "memory") {
    child.reap(true);
    throw Error(memory_message(path, limits));
  }
  // End of the pipe: the child ended; wait for it (within the deadline).
  for (;;) {
    const pid_t r = ::wait4(child.pid, &child.status, WNOHANG, &child.usage);
    if (r == child.pid) {
      child.reaped = true;
      break;
    }
    if (source.has_deadline && std::chrono::steady_clock::now() > source.deadline) {
      child.reap(true);
      throw Error(path + ": reading it took longer than the reader's limit of " +
                  std::to_string(int(limits.seconds)) + " s (raise it with --scene-limits seconds=S)");
    }
    ::usleep(2000);
  }
  if (WIFSIGNALED(child.status))
    throw Error(path + ": the scene reader crashed on it (" + signal_name(WTERMSIG(child.status)) +
                "): a corrupt or hostile file");
  throw Error(path + ": the scene reader ended without an answer (exit status " +
              std::to_string(WIFEXITED(child.status) ? WEXITSTATUS(child.status) : -1) + ")");
}

}  // namespace st
