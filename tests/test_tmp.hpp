// Force-included into every test binary (tests/CMakeLists.txt). ctest runs each test
// case in its own process, in parallel, so two cases writing "small.pack" into one
// shared folder race: SHADOWTILE_TEST_TMP is a folder of this process alone, made on
// first use and removed when the process exits normally (a crashed run leaves its
// folder for a post-mortem).
#pragma once

#include <unistd.h>

#include <filesystem>
#include <string>
#include <system_error>

namespace st::test_tmp {

inline std::filesystem::path folder_of(long pid) {
  std::string name = std::to_string(pid);
  name.insert(name.begin(), 'p');  // not "p" + to_string(): GCC 12 -O3 warns falsely (-Wrestrict)
  return std::filesystem::path(SHADOWTILE_TEST_TMP_BASE) / name;
}

struct Cleanup {
  long pid = ::getpid();
  ~Cleanup() {
    if (::getpid() != pid) return;  // a forked child leaves the parent's folder alone
    std::error_code ec;
    std::filesystem::remove_all(folder_of(pid), ec);
  }
};

inline const std::string& dir() {
  static Cleanup cleanup;  // constructed first, so destroyed after `path` below
  static const std::string path = [] {
    const auto p = folder_of(::getpid());
    std::filesystem::create_directories(p);
    return p.string();
  }();
  return path;
}

}  // namespace st::test_tmp

#define SHADOWTILE_TEST_TMP (::st::test_tmp::dir().c_str())
