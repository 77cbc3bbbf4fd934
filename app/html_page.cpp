#include "app/html_page.hpp"

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <thread>
#include <vector>

namespace st::cli {

namespace {

constexpr int kNoMatplotlib = 3;    // html_report.py's exit code when matplotlib is missing
constexpr double kTimeoutSeconds = 300;

// The generator: $SHADOWTILE_HTML_REPORT, the installed copy beside the executable
// (PREFIX/bin/shadowtile -> PREFIX/share/shadowtile/), then the source tree's.
std::string find_script() {
  namespace fs = std::filesystem;
  if (const char* e = std::getenv("SHADOWTILE_HTML_REPORT"); e && *e) return e;
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    const fs::path installed = exe.parent_path().parent_path() / "share/shadowtile/html_report.py";
    if (fs::exists(installed, ec)) return installed.string();
  }
  return SHADOWTILE_SOURCE_HTML_REPORT;
}

// Debian's python3 (where python3-matplotlib lives) before whatever python3 PATH finds
// first (a pyenv or virtualenv one often lacks matplotlib); $SHADOWTILE_PYTHON overrides.
std::string find_python() {
  if (const char* e = std::getenv("SHADOWTILE_PYTHON"); e && *e) return e;
  if (access("/usr/bin/python3", X_OK) == 0) return "/usr/bin/python3";
  return "python3";
}

std::string quoted(const std::string& s) {
  if (!s.empty() && s.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-+=.,/:@%^")
                        == std::string::npos)
    return s;
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

}  // namespace

std::string command_line() {
  std::ifstream f("/proc/self/cmdline", std::ios::binary);
  const std::string raw((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  std::string out;
  for (size_t i = 0; i < raw.size();) {
    const size_t end = raw.find('\0', i);
    const std::string arg = raw.substr(i, end == std::string::npos ? std::string::npos : end - i);
    if (!out.empty()) out.push_back(' ');
    out.append(quoted(arg));
    if (end == std::string::npos) break;
    i = end + 1;
  }
  return out;
}

bool write_html_page(const std::string& kind, const std::string& input, const std::string& out) {
  if (const char* e = std::getenv("SHADOWTILE_HTML"); e && std::string(e) == "0") {
    std::printf("html: skipped (SHADOWTILE_HTML=0)\n");
    return false;
  }
  const std::string script = find_script();
  std::error_code ec;
  if (!std::filesystem::exists(script, ec)) {
    std::printf("html: skipped (no html_report.py at %s; set SHADOWTILE_HTML_REPORT)\n", script.c_str());
    return false;
  }
  const std::string cmd = command_line();
  std::vector<std::string> args = {find_python(), script, kind, input, "-o", out, "--command", cmd};
  std::vector<char*> argv;
  for (std::string& s : args) argv.push_back(s.data());
  argv.push_back(nullptr);
  std::fflush(stdout);
  std::fflush(stderr);
  // posix_spawn, not fork: the commands that call this still have threads running. The
  // generator prints the page's path; this process prints it (last) instead.
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, "/dev/null", O_WRONLY, 0);
  pid_t pid = 0;
  const int err = posix_spawnp(&pid, argv[0], &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (err != 0) {
    std::printf("html: skipped (cannot start %s: %s)\n", argv[0], std::strerror(err));
    return false;
  }
  const auto t0 = std::chrono::steady_clock::now();
  int status = 0;
  for (;;) {
    const pid_t w = waitpid(pid, &status, WNOHANG);
    if (w == pid) break;
    if (w < 0) {
      std::printf("html: skipped (lost the generator process)\n");
      return false;
    }
    if (std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() > kTimeoutSeconds) {
      kill(pid, SIGKILL);
      waitpid(pid, &status, 0);
      std::printf("html: skipped (html_report.py ran over %.0f s)\n", kTimeoutSeconds);
      return false;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  const int rc = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  if (rc == 0) {
    std::printf("html: %s\n", out.c_str());
    return true;
  }
  if (rc == kNoMatplotlib)
    std::printf("html: skipped (matplotlib is missing: apt-get install python3-matplotlib)\n");
  else
    std::printf("html: not written (html_report.py exited %d; its message is above)\n", rc);
  return false;
}

}  // namespace st::cli
