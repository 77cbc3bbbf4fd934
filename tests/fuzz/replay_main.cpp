// Replay driver: runs a harness's LLVMFuzzerTestOneInput without libFuzzer, so every
// harness is exercised by ctest with the normal toolchain (and under the asan preset,
// with ASan/UBSan), and a crash file from scripts/fuzz can be replayed in a debugger.
//
//   <harness>_replay                      seeds + mutations (default 3000, seed 1)
//   <harness>_replay --mutations N --seed S --max-len M --seconds T
//   <harness>_replay --write-seeds DIR    writes the seeds as DIR/seed_NNN (scripts/fuzz)
//   <harness>_replay FILE|DIR...          replays the given inputs only
//
// Mutations are deterministic (a seeded mt19937_64): byte flips, bit flips, byte sets
// to boundary values (0, 0xff, 0x7f, 0x80), little-endian u32 overwrites with
// interesting values, truncations, insertions, duplications and splices of two seeds,
// stacked 1-4 deep. Stops early after --seconds so ctest stays fast under ASan.
#include <chrono>
#include <csignal>
#include <fcntl.h>
#include <unistd.h>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <iterator>
#include <random>
#include <string>

#include "tests/fuzz/fuzz_harness.hpp"

namespace {

using st::fuzz::Bytes;

Bytes read_file(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return Bytes(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// The input being run, written to ./replay-crash-<pid>.bin if it aborts or faults, so
// a failure found by mutation can be replayed (and made a regression test).
const Bytes* g_current = nullptr;

extern "C" void dump_current(int sig) {
  if (g_current) {
    char path[64];
    std::snprintf(path, sizeof path, "replay-crash-%d.bin", int(::getpid()));
    const int fd = ::open(path, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd >= 0) {
      if (::write(fd, g_current->data(), g_current->size()) < 0) {
      }
      ::close(fd);
    }
    static const char kMsg[] = "replay: failing input written to replay-crash-<pid>.bin\n";
    if (::write(2, kMsg, sizeof kMsg - 1) < 0) {
    }
  }
  std::signal(sig, SIG_DFL);
  std::raise(sig);
}

void run_one(const Bytes& input) {
  g_current = &input;
  // An exact-size heap copy: ASan then flags a read one past the end of the input.
  std::unique_ptr<std::uint8_t[]> copy(new std::uint8_t[input.size() + (input.empty() ? 1 : 0)]);
  if (!input.empty()) std::memcpy(copy.get(), input.data(), input.size());
  LLVMFuzzerTestOneInput(copy.get(), input.size());
  g_current = nullptr;
}

void mutate(Bytes& b, const std::vector<Bytes>& seeds, std::mt19937_64& rng, size_t max_len) {
  static const std::uint32_t kInteresting[] = {0u, 1u, 0x7fu, 0x80u, 0xffu, 0x100u, 0xffffu,
                                               0x10000u, 0x7fffffffu, 0x80000000u, 0xffffffffu,
                                               0xfffffffeu, 24u, 64u * 1024u};
  const int depth = 1 + int(rng() % 4);
  for (int d = 0; d < depth; ++d) {
    const size_t n = b.size();
    switch (rng() % 8) {
      case 0:  // random byte
        if (n) b[rng() % n] = std::uint8_t(rng());
        break;
      case 1:  // bit flip
        if (n) b[rng() % n] ^= std::uint8_t(1u << (rng() % 8));
        break;
      case 2: {  // boundary byte
        static const std::uint8_t kBytes[] = {0, 0xff, 0x7f, 0x80, 1};
        if (n) b[rng() % n] = kBytes[rng() % 5];
        break;
      }
      case 3: {  // interesting u32, little-endian, anywhere (lengths, counts, offsets)
        if (n >= 4) {
          const std::uint32_t v = kInteresting[rng() % std::size(kInteresting)];
          const size_t at = rng() % (n - 3);
          for (int i = 0; i < 4; ++i) b[at + i] = std::uint8_t(v >> (8 * i));
        }
        break;
      }
      case 4:  // truncation
        if (n) b.resize(rng() % n);
        break;
      case 5: {  // insertion of random bytes
        const size_t at = n ? rng() % (n + 1) : 0, len = 1 + rng() % 8;
        Bytes ins(len);
        for (auto& x : ins) x = std::uint8_t(rng());
        b.insert(b.begin() + std::ptrdiff_t(at), ins.begin(), ins.end());
        break;
      }
      case 6: {  // duplicate a range
        if (n) {
          const size_t at = rng() % n, len = 1 + rng() % std::min<size_t>(n - at, 64);
          Bytes piece(b.begin() + std::ptrdiff_t(at), b.begin() + std::ptrdiff_t(at + len));
          b.insert(b.begin() + std::ptrdiff_t(rng() % (n + 1)), piece.begin(), piece.end());
        }
        break;
      }
      case 7: {  // splice: our prefix + another seed's suffix
        const Bytes& other = seeds[rng() % seeds.size()];
        const size_t cut = n ? rng() % n : 0;
        const size_t from = other.empty() ? 0 : rng() % other.size();
        b.resize(cut);
        b.insert(b.end(), other.begin() + std::ptrdiff_t(from), other.end());
        break;
      }
    }
  }
  if (b.size() > max_len) b.resize(max_len);
}

}  // namespace

int main(int argc, char** argv) {
  size_t mutations = 3000, max_len = 1 << 20;
  std::uint64_t seed = 1;
  double seconds = 20;
  std::string write_dir;
  std::vector<std::string> inputs;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::cerr << a << " needs a value\n";
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--mutations") mutations = std::stoull(next());
    else if (a == "--seed") seed = std::stoull(next());
    else if (a == "--max-len") max_len = std::stoull(next());
    else if (a == "--seconds") seconds = std::stod(next());
    else if (a == "--write-seeds") write_dir = next();
    else inputs.push_back(a);
  }
  for (int sig : {SIGABRT, SIGSEGV, SIGBUS, SIGFPE, SIGILL}) std::signal(sig, dump_current);
  try {
    if (!inputs.empty()) {
      size_t n = 0;
      for (const std::string& in : inputs) {
        std::vector<std::filesystem::path> files;
        if (std::filesystem::is_directory(in)) {
          for (const auto& e : std::filesystem::directory_iterator(in))
            if (e.is_regular_file()) files.push_back(e.path());
        } else {
          files.push_back(in);
        }
        for (const auto& f : files) {
          run_one(read_file(f));
          ++n;
        }
      }
      std::cout << "replayed " << n << " inputs: ok\n";
      return 0;
    }
    const std::vector<Bytes> seeds = st::fuzz::seeds();
    if (seeds.empty()) {
      std::cerr << "harness has no seeds\n";
      return 1;
    }
    if (!write_dir.empty()) {
      std::filesystem::create_directories(write_dir);
      size_t total = 0;
      for (size_t i = 0; i < seeds.size(); ++i) {
        char name[32];
        std::snprintf(name, sizeof name, "seed_%03zu", i);
        std::ofstream(std::filesystem::path(write_dir) / name, std::ios::binary)
            .write(reinterpret_cast<const char*>(seeds[i].data()), std::streamsize(seeds[i].size()));
        total += seeds[i].size();
      }
      std::cout << "wrote " << seeds.size() << " seeds (" << total << " bytes) to " << write_dir << "\n";
      return 0;
    }
    const auto start = std::chrono::steady_clock::now();
    for (const Bytes& s : seeds) run_one(s);
    const size_t seeds_accepted = st::fuzz::accepted_inputs;
    if (seeds_accepted != 0 && seeds_accepted != seeds.size()) {
      std::cerr << "only " << seeds_accepted << " of " << seeds.size() << " seeds accepted\n";
      return 1;
    }
    std::mt19937_64 rng(seed);
    size_t done = 0;
    for (; done < mutations; ++done) {
      if ((done & 63) == 0 && std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() > seconds)
        break;
      Bytes b = seeds[rng() % seeds.size()];
      mutate(b, seeds, rng, max_len);
      run_one(b);
    }
    const double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::cout << seeds.size() << " seeds + " << done << " mutated inputs in " << took << " s, "
              << st::fuzz::accepted_inputs - seeds_accepted << " mutated inputs accepted: ok\n";
  } catch (const std::exception& e) {
    std::cerr << "replay: uncaught " << e.what() << "\n";
    return 1;
  }
  return 0;
}
