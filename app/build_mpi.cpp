#include "app/build_mpi.hpp"

#include <mpi.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <cstdio>
#include <cstring>
#include <exception>
#include <thread>
#include <vector>

#include "common/error.hpp"

namespace st::cli {
namespace {

// Message tags (all payloads are bytes; integers little-endian u32).
constexpr int kTagRequest = 1;  // worker -> 0: u32 cells wanted
constexpr int kTagAssign = 2;   // 0 -> worker: (u32 cx, u32 cy)*, empty = no more
constexpr int kTagResult = 3;   // worker -> 0: one cell's journal bytes
constexpr int kTagError = 4;    // worker -> 0: text

// OpenMPI's blocking receives spin on a core; the build's threads need them, so the
// waiting side polls with short sleeps instead.
MPI_Status wait_message(int source, int tag) {
  for (;;) {
    int flag = 0;
    MPI_Status st;
    MPI_Iprobe(source, tag, MPI_COMM_WORLD, &flag, &st);
    if (flag) return st;
    std::this_thread::sleep_for(std::chrono::microseconds(200));
  }
}

std::vector<uint8_t> receive(const MPI_Status& st) {
  int n = 0;
  MPI_Get_count(&st, MPI_BYTE, &n);
  std::vector<uint8_t> buf(size_t(std::max(n, 0)));
  MPI_Recv(buf.data(), n, MPI_BYTE, st.MPI_SOURCE, st.MPI_TAG, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
  return buf;
}

void send(const void* data, size_t n, int dest, int tag) {
  MPI_Send(data, int(n), MPI_BYTE, dest, tag, MPI_COMM_WORLD);
}

uint32_t load_u32(const uint8_t* p) {
  uint32_t v;
  std::memcpy(&v, p, 4);
  return v;
}

std::string host_name() {
  char buf[256] = {};
  ::gethostname(buf, sizeof buf - 1);
  return buf;
}

// Rank 0's side: hands cells to the other ranks and appends what they send back.
class MpiRemote final : public RemoteCells {
 public:
  explicit MpiRemote(int ranks) : figures_{ranks, std::vector<uint64_t>(size_t(ranks), 0), 0} {}
  void run(const Take& take, const Append& append) override {
    int active = figures_.ranks - 1;
    uint64_t outstanding = 0;
    while (active > 0 || outstanding > 0) {
      const MPI_Status st = wait_message(MPI_ANY_SOURCE, MPI_ANY_TAG);
      const std::vector<uint8_t> buf = receive(st);
      const int from = st.MPI_SOURCE;
      if (st.MPI_TAG == kTagRequest && buf.size() == 4) {
        const uint32_t want = std::min<uint32_t>(load_u32(buf.data()), 1024);
        std::vector<uint32_t> cells;
        for (uint32_t i = 0; i < want; ++i) {
          auto c = take();
          if (!c) break;
          cells.push_back(c->first);
          cells.push_back(c->second);
        }
        send(cells.data(), cells.size() * 4, from, kTagAssign);
        outstanding += cells.size() / 2;
        if (cells.empty()) --active;
      } else if (st.MPI_TAG == kTagResult && outstanding > 0) {
        figures_.bytes_received += buf.size();
        append(buf);
        --outstanding;
        ++figures_.cells_by_rank[size_t(from)];
      } else if (st.MPI_TAG == kTagError) {
        throw Error("rank " + std::to_string(from) + " failed: " + std::string(buf.begin(), buf.end()));
      } else {
        throw Error("rank " + std::to_string(from) + " sent an unexpected message (tag " +
                    std::to_string(st.MPI_TAG) + ", " + std::to_string(buf.size()) + " bytes)");
      }
    }
  }
  MpiBuildFigures figures_;
};

// Ranks 1..N-1: ask for as many cells as there are threads, build them, send them back.
void worker_rank(const CellBuilder& builder, int rank) {
  const uint32_t threads = std::max(1u, std::thread::hardware_concurrency());
  for (;;) {
    send(&threads, 4, 0, kTagRequest);
    const std::vector<uint8_t> msg = receive(wait_message(0, kTagAssign));
    const size_t n = msg.size() / 8;
    if (n == 0) return;
    std::vector<std::vector<uint8_t>> out(n);
    std::vector<std::string> errors(n);
    std::vector<std::thread> pool;
    std::atomic<size_t> next{0};
    for (uint32_t t = 0; t < std::min<size_t>(threads, n); ++t)
      pool.emplace_back([&] {
        for (size_t i = next++; i < n; i = next++) {
          try {
            out[i] = builder.build(load_u32(msg.data() + 8 * i), load_u32(msg.data() + 8 * i + 4));
          } catch (const std::exception& e) {
            errors[i] = e.what();
          }
        }
      });
    for (auto& t : pool) t.join();
    for (size_t i = 0; i < n; ++i) {
      if (!errors[i].empty()) {
        const std::string text = "on " + host_name() + " (rank " + std::to_string(rank) + "): " + errors[i];
        send(text.data(), text.size(), 0, kTagError);
        // Rank 0 aborts the job; wait for it rather than end on our own.
        for (;;) std::this_thread::sleep_for(std::chrono::seconds(1));
      }
      send(out[i].data(), out[i].size(), 0, kTagResult);
    }
  }
}

}  // namespace

int mpi_rank() {
  int initialized = 0;
  MPI_Initialized(&initialized);
  if (!initialized) return 0;
  int rank = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  return rank;
}

void mpi_init(int* argc, char*** argv) {
  int provided = 0;
  MPI_Init_thread(argc, argv, MPI_THREAD_SERIALIZED, &provided);
  if (provided < MPI_THREAD_SERIALIZED) {
    MPI_Finalize();
    throw Error("--mpi: the MPI library does not provide MPI_THREAD_SERIALIZED");
  }
}

std::optional<std::pair<MapBuildReport, MpiBuildFigures>> build_map_mpi(const Scene& scene, const LightSpace& light,
                                                                        MapBuildOptions options,
                                                                        const std::string& out_path) {
  int rank = 0, ranks = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &ranks);
  if (rank != 0) {
    try {
      CellBuilder builder(scene, light, options);
      worker_rank(builder, rank);
    } catch (const std::exception& e) {
      const std::string text = "on " + host_name() + " (rank " + std::to_string(rank) + "): " + e.what();
      send(text.data(), text.size(), 0, kTagError);
      for (;;) std::this_thread::sleep_for(std::chrono::seconds(1));
    }
    MPI_Finalize();
    return std::nullopt;
  }
  MpiRemote remote(ranks);
  options.remote = ranks > 1 ? &remote : nullptr;
  try {
    MapBuildReport r = build_map(scene, light, options, out_path);
    remote.figures_.cells_by_rank[0] = r.cells_built;
    for (size_t i = 1; i < remote.figures_.cells_by_rank.size(); ++i) {
      remote.figures_.cells_by_rank[0] -= remote.figures_.cells_by_rank[i];
      // Every cell handed out is traced whole: 4^(L-K) texels.
      r.texels_traced += remote.figures_.cells_by_rank[i] << (2 * (r.map_level - r.skip_level));
    }
    MPI_Finalize();
    return std::make_pair(std::move(r), remote.figures_);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "shadowtile: error: build --mpi (rank 0 of %d on %s): %s; '%s.tmp' keeps the cells "
                 "appended so far: run the same command with --resume\n", ranks, host_name().c_str(), e.what(),
                 out_path.c_str());
    std::fflush(stderr);
    MPI_Abort(MPI_COMM_WORLD, 1);
    std::_Exit(1);
  }
}

}  // namespace st::cli
