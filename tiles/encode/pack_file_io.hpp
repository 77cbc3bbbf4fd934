// File I/O shared by the pack writer's translation units (pack_writer.cpp,
// pack_writer_dictionary.cpp): positioned reads and writes that retry on EINTR and name
// the file and byte in their one-line errors, and the directory fsync after a rename.
#pragma once
#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>

#include "common/error.hpp"

namespace st::pack_io {

inline std::string sys_error(const std::string& what) { return what + ": " + std::strerror(errno); }

// Reads exactly out.size() bytes at `offset`; `what` names the file in errors.
inline void pread_all(int fd, uint64_t offset, std::span<uint8_t> out, const std::string& what) {
  size_t done = 0;
  while (done < out.size()) {
    const ssize_t n = ::pread(fd, out.data() + done, out.size() - done, off_t(offset + done));
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) throw Error(sys_error(what + ": read"));
    if (n == 0) throw Error(what + ": unexpected end of file at byte " + std::to_string(offset + done));
    done += size_t(n);
  }
}

// Writes all of `bytes` at `offset`; `what` names the file in errors.
inline void pwrite_all(int fd, uint64_t offset, std::span<const uint8_t> bytes, const std::string& what) {
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::pwrite(fd, bytes.data() + done, bytes.size() - done, off_t(offset + done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) throw Error(sys_error(what + ": write at byte " + std::to_string(offset + done)));
    done += size_t(n);
  }
}

// Makes a rename into `path`'s directory durable (best effort: the rename already happened).
inline void fsync_dir_of(const std::string& path) {
  const size_t slash = path.rfind('/');
  const std::string dir = slash == std::string::npos ? "." : slash == 0 ? "/" : path.substr(0, slash);
  const int d = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (d < 0) return;
  ::fsync(d);
  ::close(d);
}

}  // namespace st::pack_io
