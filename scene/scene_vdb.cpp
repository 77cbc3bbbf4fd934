// load_vdb_volume: one float grid of an OpenVDB file as a dense st::Volume (the rules are
// in scene_volumes.hpp). The only file of the project that includes OpenVDB; without it
// (SHADOWTILE_OPENVDB=OFF) every .vdb scene fails with one line saying so.
#include "scene/scene_volumes.hpp"

#ifdef SHADOWTILE_HAVE_OPENVDB
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#endif

#include <fcntl.h>
#include <signal.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <new>
#include <system_error>
#include <thread>

#include "common/error.hpp"
#include "common/sanitizer.hpp"
#include "common/text.hpp"

namespace st {

#ifndef SHADOWTILE_HAVE_OPENVDB

bool vdb_supported() { return false; }

Volume load_vdb_volume(const std::string& path, const VdbOptions&) {
  throw Error(path + ": this shadowtile was built without OpenVDB (install libopenvdb-dev, "
                     "reconfigure with SHADOWTILE_OPENVDB=ON)");
}

#else

bool vdb_supported() { return true; }

namespace {

// Where one axis of the output (world, +Y up) comes from: the grid's world axis `src`,
// negated when `sign` < 0 (UpAxis::z turns (x, y, z) into (x, z, -y), like mesh files).
struct AxisMap {
  int src[3];
  double sign[3];
};
AxisMap axis_map(UpAxis up) {
  if (up == UpAxis::z) return {{0, 2, 1}, {1, 1, -1}};
  return {{0, 1, 2}, {1, 1, 1}};
}

std::string coord_text(const openvdb::Coord& c) {
  return "(" + std::to_string(c.x()) + ", " + std::to_string(c.y()) + ", " + std::to_string(c.z()) + ")";
}

// Voxels of a box [lo, hi] (inclusive), saturating instead of overflowing.
uint64_t box_voxels(const openvdb::Coord& lo, const openvdb::Coord& hi) {
  uint64_t n = 1;
  for (int k = 0; k < 3; ++k) {
    if (hi[k] < lo[k]) return 0;
    const uint64_t d = uint64_t(int64_t(hi[k]) - int64_t(lo[k]) + 1);
    n = n > UINT64_MAX / d ? UINT64_MAX : n * d;
  }
  return n;
}

[[noreturn]] void fail(const std::string& where, const std::string& what) {
  throw Error(where + ": " + what);
}

void check_budget(const std::string& where, uint64_t voxels, const openvdb::Coord& lo,
                  const openvdb::Coord& hi, uint64_t budget, const char* from) {
  if (voxels > budget)
    fail(where, "active bounding box " + coord_text(lo) + " .. " + coord_text(hi) + " (" + from +
                    ") holds " + std::to_string(voxels) + " voxels, over the dense budget of " +
                    std::to_string(budget) + " (max_voxels=N raises it up to " +
                    std::to_string(kVdbMaxVoxels) + ")");
}

// The structure of a .vdb file up to each grid's topology, checked before OpenVDB reads
// it: OpenVDB's reader trusts every length it reads (a flipped string length makes it
// allocate gigabytes) and reads a truncated grid without complaint (the missing bytes
// become whatever the failed stream left). The layout (OpenVDB io/Archive, format
// versions 222-224):
//   int64 magic "VDB ", uint32 version, uint32 library major, minor, uint8 has offsets,
//   36 ASCII bytes of UUID, the file's metadata map, int32 grid count, then per grid:
//   descriptor (string unique name, string type, string instance parent, int64 grid,
//   block and end offsets), at the grid offset: uint32 compression, the grid's metadata
//   map, the transform (string map type, then its values), topology, and at the block
//   offset the voxel buffers up to the end offset, where the next descriptor starts.
//   A string is a uint32 length and its bytes; a metadata map an int32 count of (string
//   name, string type, int32 size, size bytes).
// Every length is checked against the bytes left, every offset against the file's size
// and its predecessor; a grid that ends past the end of the file is a truncated file.
// Inside a float grid, the root's tile and child counts are checked against the bytes
// of topology; the rest of the topology and the buffers are left to OpenVDB (its
// decompressors check their sizes; each node's children are bounded by the masks it
// read, so memory stays within a few dozen times the file's size unless the stream
// fails mid-topology, where OpenVDB keeps going on whatever its buffers held).
class VdbStructure {
 public:
  VdbStructure(const std::string& path, const std::string& where) : where_(where), in_(path, std::ios::binary) {
    std::error_code ec;
    size_ = std::filesystem::file_size(path, ec);
    if (ec || !in_) fail(where_, "cannot open it");
  }

  void check() {
    if (size_ < 8 || u64() != 0x56444220u) fail(where_, "not a VDB file (no \"VDB \" magic number)");
    const uint32_t version = u32();
    if (version < 222 || version > openvdb::OPENVDB_FILE_VERSION)
      fail(where_, "VDB file format version " + std::to_string(version) + " (this reader takes 222 to " +
                       std::to_string(openvdb::OPENVDB_FILE_VERSION) + ": re-save it with OpenVDB 4 or later)");
    u32(), u32();  // library version
    if (u8() != 1) fail(where_, "the file has no grid offsets (written as a stream): re-save it as a file");
    skip(36, "UUID");
    meta_map("file metadata");
    const int32_t grids = i32();
    if (grids < 0 || uint64_t(grids) > left() / 40) fail(where_, "bad grid count " + std::to_string(grids));
    for (int32_t g = 0; g < grids; ++g) {
      const std::string what = "grid descriptor " + std::to_string(g);
      string(what + " name");
      const std::string type = string(what + " type");
      const bool instance = !string(what + " instance parent").empty();
      const int64_t grid = i64(), block = i64(), end = i64();
      const int64_t size = int64_t(size_);
      if (grid != int64_t(pos_) || end < grid || (!instance && (block < grid || block > end)))
        fail(where_, what + ": inconsistent offsets (grid " + std::to_string(grid) + ", blocks " +
                         std::to_string(block) + ", end " + std::to_string(end) + ")");
      if (end > size)
        fail(where_, "truncated: " + what + " ends at byte " + std::to_string(end) + " of a " +
                         std::to_string(size_) + "-byte file");
      u32();  // compression flags
      meta_map(what + " metadata");
      const std::string map = string(what + " transform type");
      if (map.size() > 64) fail(where_, what + ": implausible transform type");
      if (type == "Tree_float_5_4_3" && !instance) root_counts(map, uint64_t(block), what);
      seek(uint64_t(end));
    }
  }

 private:
  // A float tree's root (after a linear map's values): int32 buffer count, float
  // background, uint32 tile and child counts. Each tile takes 17 bytes of topology and each
  // child at least its two 4096-byte node masks, so both counts are bounded by the bytes
  // before the buffers; beyond the root every node's children are bounded by masks it
  // read from the file.
  void root_counts(const std::string& map, uint64_t block, const std::string& what) {
    uint64_t values = 0;
    if (map == "AffineMap" || map == "UnitaryMap") values = 128;
    else if (map == "ScaleMap" || map == "UniformScaleMap") values = 120;
    else if (map == "ScaleTranslateMap" || map == "UniformScaleTranslateMap") values = 144;
    else if (map == "TranslationMap") values = 24;
    else return;  // frustum or unknown: refused before its topology is read
    skip(values + 4 + 4, what + " transform");
    const uint32_t tiles = value<uint32_t>("tile count"), children = value<uint32_t>("child count");
    const uint64_t topology = block > pos_ ? block - pos_ : 0;
    if (uint64_t(tiles) * 17 + uint64_t(children) * 8204 > topology)
      fail(where_, what + ": corrupt topology (" + std::to_string(tiles) + " root tiles and " +
                       std::to_string(children) + " root children in " + std::to_string(topology) + " bytes)");
  }
  uint64_t left() const { return size_ - pos_; }
  void need(uint64_t n, const std::string& what) {
    if (n > left())
      fail(where_, "truncated or corrupt: " + what + " needs " + std::to_string(n) + " bytes at offset " +
                       std::to_string(pos_) + ", " + std::to_string(left()) + " left");
  }
  void read(void* p, uint64_t n, const std::string& what) {
    need(n, what);
    in_.read(static_cast<char*>(p), std::streamsize(n));
    if (!in_) fail(where_, "cannot read " + what + " at offset " + std::to_string(pos_));
    pos_ += n;
  }
  template <class T>
  T value(const char* what) {
    T v{};
    read(&v, sizeof v, what);
    return v;
  }
  uint64_t u64() { return value<uint64_t>("header"); }
  int64_t i64() { return value<int64_t>("offset"); }
  uint32_t u32() { return value<uint32_t>("header"); }
  int32_t i32() { return value<int32_t>("count"); }
  uint8_t u8() { return value<uint8_t>("flag"); }
  void seek(uint64_t to) {
    in_.seekg(std::streamoff(to));
    if (!in_) fail(where_, "cannot seek to offset " + std::to_string(to));
    pos_ = to;
  }
  void skip(uint64_t n, const std::string& what) {
    need(n, what);
    seek(pos_ + n);
  }
  std::string string(const std::string& what) {
    const uint32_t n = value<uint32_t>("string length");
    need(n, what);
    if (n > 4096) {  // names and type names: only metadata values may be long
      skip(n, what);
      return std::string(4097, ' ');
    }
    std::string s(n, '\0');
    read(s.data(), n, what);
    return s;
  }
  void meta_map(const std::string& what) {
    const int32_t n = value<int32_t>("metadata count");
    if (n < 0 || uint64_t(n) > left() / 12) fail(where_, what + ": bad entry count " + std::to_string(n));
    for (int32_t i = 0; i < n; ++i) {
      if (string(what + " name").size() > 4096 || string(what + " type").size() > 4096)
        fail(where_, what + ": implausible entry name");
      const int32_t bytes = value<int32_t>("metadata size");
      if (bytes < 0) fail(where_, what + ": negative value size");
      skip(uint64_t(bytes), what + " value");
    }
  }

  std::string where_;
  std::ifstream in_;
  uint64_t size_ = 0, pos_ = 0;
};

// What OpenVDB makes of the file (after VdbStructure passed): the grid made dense. Runs
// in the reader's child process (read_isolated).
Volume read_openvdb(const std::string& path, const VdbOptions& o, const std::string& where) {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });

  openvdb::io::File file(path);
  file.open(false);  // no delayed loading: the whole grid is read here, not mapped lazily
  if (!file.hasGrid(o.grid)) {
    std::string names;
    int listed = 0;
    for (auto it = file.beginName(); it != file.endName() && listed < 8; ++it, ++listed)
      names += (names.empty() ? "" : ", ") + printable_text(it.gridName());
    fail(where, "no such grid in the file (grids: " + (names.empty() ? "none" : names) + "); pick one with grid=NAME");
  }
  // Type, class, transform and the writer's statistics, before any voxel is read.
  const openvdb::GridBase::Ptr meta = file.readGridMetadata(o.grid);
  if (!meta->isType<openvdb::FloatGrid>())
    fail(where, "is a grid of " + printable_text(meta->valueType()) + ", not float (a density grid is a FloatGrid)");
  if (meta->getGridClass() == openvdb::GRID_LEVEL_SET)
    fail(where, "is a level set (a signed distance), not a density (fog volume) grid");
  const openvdb::math::MapBase::ConstPtr map = meta->transform().baseMap();
  if (!map->isLinear())
    fail(where, "has a non-linear (" + map->type() + ", e.g. frustum) transform; only scale + translate grids are read");
  const openvdb::math::Mat4d m = map->getAffineMap()->getMat4();
  // OpenVDB maps row vectors: world_k = sum_i index_i m(i, k) + m(3, k).
  double scale[3], shift[3], largest = 0;
  for (int k = 0; k < 3; ++k) {
    scale[k] = m(k, k), shift[k] = m(3, k);
    largest = std::max(largest, std::fabs(scale[k]));
    if (!std::isfinite(scale[k]) || scale[k] == 0 || !std::isfinite(shift[k]))
      fail(where, "its transform has a zero or non-finite voxel size or translation");
  }
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k)
      if (i != k && !(std::fabs(m(i, k)) <= 1e-9 * largest))
        fail(where, "its transform rotates or shears the index axes; only axis-aligned (scale + "
                    "translate) grids are read: resample it axis-aligned");
  {
    using V3 = openvdb::Vec3IMetadata;
    const auto lo = meta->getMetadata<V3>(openvdb::GridBase::META_FILE_BBOX_MIN);
    const auto hi = meta->getMetadata<V3>(openvdb::GridBase::META_FILE_BBOX_MAX);
    if (lo && hi) {
      const openvdb::Coord a(lo->value()), b(hi->value());
      check_budget(where, box_voxels(a, b), a, b, o.max_voxels, "from the file's statistics");
    }
    const auto bytes = meta->getMetadata<openvdb::Int64Metadata>(openvdb::GridBase::META_FILE_MEM_BYTES);
    // The sparse grid of a box within the budget takes no more than the dense one plus
    // its topology; a file that says otherwise is refused before it is read.
    const uint64_t sparse_limit = 8 * o.max_voxels + (uint64_t(64) << 20);
    if (bytes && (bytes->value() < 0 || uint64_t(bytes->value()) > sparse_limit))
      fail(where, "the file says the grid takes " + std::to_string(bytes->value()) +
                      " bytes in memory, over " + std::to_string(sparse_limit) + " for max_voxels=" +
                      std::to_string(o.max_voxels));
  }

  const openvdb::FloatGrid::Ptr grid = openvdb::gridPtrCast<openvdb::FloatGrid>(file.readGrid(o.grid));
  file.close();
  if (!grid) fail(where, "is not a float grid");
  const openvdb::CoordBBox box = grid->evalActiveVoxelBoundingBox();
  if (box.empty()) fail(where, "has no active voxels");
  const uint64_t voxels = box_voxels(box.min(), box.max());
  check_budget(where, voxels, box.min(), box.max(), o.max_voxels, "of the grid read");

  const AxisMap am = axis_map(o.up);
  Volume v;
  v.name = path + ":" + o.grid;
  const double sigma = o.sigma;
  v.sigma = {float(sigma), float(sigma), float(sigma)};
  uint32_t n[3];
  double coef[3], lo[3], hi[3];  // output axis a: world = coef[a] * index[src] + ...
  for (int a = 0; a < 3; ++a) {
    const int s = am.src[a];
    n[a] = uint32_t(int64_t(box.max()[s]) - int64_t(box.min()[s]) + 1);
    coef[a] = am.sign[a] * scale[s];
    const double e0 = am.sign[a] * (scale[s] * (box.min()[s] - 0.5) + shift[s]);
    const double e1 = am.sign[a] * (scale[s] * (box.max()[s] + 0.5) + shift[s]);
    lo[a] = std::min(e0, e1);
    hi[a] = std::max(e0, e1);
  }
  v.bounds.lo = {lo[0], lo[1], lo[2]};
  v.bounds.hi = {hi[0], hi[1], hi[2]};
  if (!is_finite(v.bounds.lo) || !is_finite(v.bounds.hi))
    fail(where, "its world bounds are not finite");
  v.nx = n[0], v.ny = n[1], v.nz = n[2];
  v.density.assign(voxels, 0.0f);
  // Dense position of index voxel ijk along output axis a (increasing with world).
  auto dense = [&](const openvdb::Coord& ijk) {
    size_t c[3];
    for (int a = 0; a < 3; ++a) {
      const int s = am.src[a];
      c[a] = coef[a] > 0 ? size_t(int64_t(ijk[s]) - box.min()[s]) : size_t(int64_t(box.max()[s]) - ijk[s]);
    }
    return (c[2] * v.ny + c[1]) * v.nx + c[0];
  };
  auto put = [&](const openvdb::Coord& ijk, float value) {
    const double d = double(value) * o.scale;
    if (!std::isfinite(d) || d < 0 || d > 3.4e38)
      fail(where, "voxel " + coord_text(ijk) + " has density " + std::to_string(value) +
                      " (times scale " + std::to_string(o.scale) + "): not finite or negative");
    v.density[dense(ijk)] = float(d);
  };
  for (auto it = grid->cbeginValueOn(); it; ++it) {
    if (it.isVoxelValue()) {
      put(it.getCoord(), *it);
      continue;
    }
    // An active tile: every voxel of it (inside the active box, so within the budget).
    const openvdb::CoordBBox t = it.getBoundingBox();
    for (int z = t.min().z(); z <= t.max().z(); ++z)
      for (int y = t.min().y(); y <= t.max().y(); ++y)
        for (int x = t.min().x(); x <= t.max().x(); ++x) put(openvdb::Coord(x, y, z), *it);
  }
  return v;
}

// The child's answer, in memory shared with the parent, followed by the densities.
struct ChildAnswer {
  uint32_t status = 0;  // kAnswer*
  uint32_t n[3] = {0, 0, 0};
  double lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0};
  char message[1024] = {};
};
constexpr uint32_t kAnswerNone = 0, kAnswerVolume = 1, kAnswerError = 2;
constexpr size_t kDensityOffset = (sizeof(ChildAnswer) + 63) / 64 * 64;
constexpr auto kReaderTimeout = std::chrono::seconds(600);


// The child's virtual memory now (from /proc/self/statm), 0 if unknown.
uint64_t address_space_bytes() {
  std::ifstream statm("/proc/self/statm");
  uint64_t pages = 0;
  if (!(statm >> pages)) return 0;
  return pages * uint64_t(::sysconf(_SC_PAGESIZE));
}

void put_message(ChildAnswer& a, const std::string& text) {
  const size_t n = std::min(text.size(), sizeof a.message - 1);
  std::memcpy(a.message, text.data(), n);
  a.message[n] = '\0';
  a.status = kAnswerError;
}

// The child: reads the grid with OpenVDB and leaves the answer in `shared`. Never
// returns (it must not unwind into the parent's stack).
[[noreturn]] void child_read(const std::string& path, const VdbOptions& o, const std::string& where,
                             void* shared) {
  auto& answer = *static_cast<ChildAnswer*>(shared);
  // OpenVDB warns on stderr about what it reads ("multi-buffer trees ..."); the parent
  // reports in one line instead.
  const int devnull = ::open("/dev/null", O_WRONLY | O_CLOEXEC);
  if (devnull >= 0) ::dup2(devnull, 2);
  const rlimit no_core{0, 0};  // a crash here is reported by the parent, not dumped
  ::setrlimit(RLIMIT_CORE, &no_core);
  // Memory: the sparse grid (checked against 8 x max_voxels + 64 MiB from the file's
  // statistics when it has them), the dense copy and OpenVDB's buffers, with room; a
  // file that makes OpenVDB allocate past this fails with "out of memory" instead of
  // taking the machine. (Not under ASan, which reserves terabytes of shadow memory.)
  if (!kAddressSanitizer) {
    const uint64_t now = address_space_bytes();
    if (now > 0) {
      const uint64_t limit = now + (uint64_t(1) << 30) + 16 * o.max_voxels;
      const rlimit r{rlim_t(limit), rlim_t(limit)};
      ::setrlimit(RLIMIT_AS, &r);
    }
  }
  try {
    const Volume v = read_openvdb(path, o, where);
    answer.n[0] = v.nx, answer.n[1] = v.ny, answer.n[2] = v.nz;
    answer.lo[0] = v.bounds.lo.x, answer.lo[1] = v.bounds.lo.y, answer.lo[2] = v.bounds.lo.z;
    answer.hi[0] = v.bounds.hi.x, answer.hi[1] = v.bounds.hi.y, answer.hi[2] = v.bounds.hi.z;
    std::memcpy(static_cast<char*>(shared) + kDensityOffset, v.density.data(), v.density.size() * sizeof(float));
    answer.status = kAnswerVolume;
    ::_exit(0);
  } catch (const Error& e) {
    put_message(answer, e.what());
  } catch (const std::bad_alloc&) {
    put_message(answer, where + ": out of memory while reading it (the reader's limit is " +
                            std::to_string(((uint64_t(1) << 30) + 16 * o.max_voxels) >> 20) +
                            " MiB above its start, from max_voxels)");
  } catch (const std::exception& e) {
    // OpenVDB's own errors (IoError on a truncated or foreign file, a bad compression
    // stream, an unknown grid type): one line.
    std::string why = e.what();
    for (char& c : why)
      if (c == '\n' || c == '\r') c = ' ';
    put_message(answer, where + ": cannot read it: " + printable_text(why));
  } catch (...) {
    put_message(answer, where + ": cannot read it (an unknown error in OpenVDB)");
  }
  ::_exit(1);
}

// OpenVDB trusts what it reads beyond the structure VdbStructure checks (a voxel
// buffer's compressed size becomes an allocation; a corrupt topology corrupts its heap:
// both found by tests/fuzz/scene_vdb_fuzz.cpp), so it reads in a child process with a
// memory limit and a timeout, and hands the dense grid back through shared memory. A
// file that crashes it, exhausts the limit or hangs it is one line of error here.
Volume read_isolated(const std::string& path, const VdbOptions& o, const std::string& where) {
  const size_t bytes = kDensityOffset + size_t(o.max_voxels) * sizeof(float);
  void* shared = ::mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_SHARED | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
  if (shared == MAP_FAILED) fail(where, std::string("cannot map memory for the reader: ") + std::strerror(errno));
  struct Unmap {
    void* p;
    size_t n;
    ~Unmap() { ::munmap(p, n); }
  } unmap{shared, bytes};
  new (shared) ChildAnswer();
  std::fflush(nullptr);  // nothing buffered is written twice
  const pid_t pid = ::fork();
  if (pid < 0) fail(where, std::string("cannot start the reader: ") + std::strerror(errno));
  if (pid == 0) child_read(path, o, where, shared);
  int status = 0;
  const auto deadline = std::chrono::steady_clock::now() + kReaderTimeout;
  auto pause = std::chrono::microseconds(50);
  for (;;) {
    const pid_t r = ::waitpid(pid, &status, WNOHANG);
    if (r == pid) break;
    if (r < 0 && errno != EINTR) fail(where, std::string("lost the reader: ") + std::strerror(errno));
    if (std::chrono::steady_clock::now() > deadline) {
      ::kill(pid, SIGKILL);
      ::waitpid(pid, &status, 0);
      fail(where, "OpenVDB did not finish reading it within " + std::to_string(kReaderTimeout.count()) + " s");
    }
    std::this_thread::sleep_for(pause);
    pause = std::min(pause * 2, std::chrono::microseconds(20000));
  }
  const auto& answer = *static_cast<const ChildAnswer*>(shared);
  if (WIFSIGNALED(status))
    fail(where, "OpenVDB crashed reading it (signal " + std::to_string(WTERMSIG(status)) +
                    "): a corrupt or hostile file");
  if (answer.status == kAnswerError) {
    std::string m(answer.message, strnlen(answer.message, sizeof answer.message));
    throw Error(m);
  }
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0 || answer.status != kAnswerVolume)
    fail(where, "the reader ended without an answer (exit status " + std::to_string(status) + ")");
  Volume v;
  v.name = path + ":" + o.grid;
  v.sigma = {float(o.sigma), float(o.sigma), float(o.sigma)};
  v.nx = answer.n[0], v.ny = answer.n[1], v.nz = answer.n[2];
  const uint64_t voxels = uint64_t(v.nx) * v.ny * v.nz;
  if (voxels == 0 || voxels > o.max_voxels) fail(where, "the reader answered an impossible grid size");
  v.bounds.lo = {answer.lo[0], answer.lo[1], answer.lo[2]};
  v.bounds.hi = {answer.hi[0], answer.hi[1], answer.hi[2]};
  const auto* d = reinterpret_cast<const float*>(static_cast<const char*>(shared) + kDensityOffset);
  v.density.assign(d, d + voxels);
  return v;
}

Volume read_grid(const std::string& path, const VdbOptions& o) {
  const std::string where = "vdb '" + printable_text(path) + "' grid '" + printable_text(o.grid) + "'";
  {
    std::error_code ec;
    const auto status = std::filesystem::status(path, ec);
    if (ec || !std::filesystem::exists(status)) throw Error("scene file not found: " + printable_text(path));
    if (!std::filesystem::is_regular_file(status))
      throw Error("scene path is not a regular file: " + printable_text(path));
  }
  VdbStructure(path, where).check();
  return read_isolated(path, o, where);
}

}  // namespace

Volume load_vdb_volume(const std::string& path, const VdbOptions& o) {
  if (o.max_voxels == 0 || o.max_voxels > kVdbMaxVoxels)
    throw Error("vdb '" + printable_text(path) + "': max_voxels must be in [1, " + std::to_string(kVdbMaxVoxels) + "]");
  if (!(o.scale >= 0) || !std::isfinite(o.scale) || !(o.sigma >= 0) || !std::isfinite(o.sigma))
    throw Error("vdb '" + printable_text(path) + "': scale and sigma must be finite and >= 0");
  try {
    return read_grid(path, o);
  } catch (const std::bad_alloc&) {
    throw Error("vdb '" + printable_text(path) + "' grid '" + printable_text(o.grid) +
                "': out of memory while reading it");
  }
}

#endif

}  // namespace st
