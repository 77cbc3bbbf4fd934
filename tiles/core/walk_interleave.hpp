// Interleaved tree walks (the batched soft-shadow lookups of stack_lookup.cpp and
// stack_map.cpp): a walk down a pointer tree stalls on each node it has not read yet, one
// dependent cache miss after another, and a soft lookup's walks (one per light sample)
// miss about one node per sample in octrees larger than the cache (MHOCT.md "Lookups").
// The walks of different points are independent, so a batch runs up to kLanes points at
// once, round robin, in the manner of asynchronous memory access chaining (Kocberber et
// al. 2015, "AMAC"): a lane runs until it steps into a node it has to wait for, prefetches
// that node's word and yields to the next lane, so up to kLanes misses are in flight
// together. Each lane's sequence of steps is exactly its point's own walk, so the answers
// are the serial lookups' bit for bit.
#pragma once
#include <cstddef>
#include <cstdint>
#include <utility>

namespace st {

// Lanes in flight: enough misses to cover the memory latency (about 100-300 ns against a
// few ns of work per step), few enough that the lanes' state stays in L1.
inline constexpr uint32_t kWalkLanes = 16;

// Runs jobs 0 .. count-1. start(lane, i) sets a lane up for job i; run(lane) advances it
// and returns true when it yields (a prefetch is in flight), false when its job is done
// (the lane then takes the next job). Lane is default-constructible and copyable.
template <class Lane, class Start, class Run>
void run_interleaved(size_t count, Start&& start, Run&& run) {
  Lane lanes[kWalkLanes];
  size_t next = 0;
  uint32_t active = 0;
  while (active < kWalkLanes && next < count) start(lanes[active++], next++);
  while (active) {
    for (uint32_t j = 0; j < active;) {
      if (run(lanes[j])) {
        ++j;
      } else if (next < count) {
        start(lanes[j++], next++);
      } else if (j != --active) {
        lanes[j] = lanes[active];  // the last lane takes this slot and runs next
      }
    }
  }
}

// The cache line of an address (64-byte lines, x86-64 and most ARM cores).
inline uintptr_t cache_line(const void* p) { return reinterpret_cast<uintptr_t>(p) >> 6; }

// Steps a resumable walk (a tree with along_next / along_step, as MhOctree) until it ends
// (false: along_value answers) or steps onto a node on another cache line than the one it
// stood on (true: that node is prefetched and the caller's lane yields).
template <class Tree, class Path, class Walk>
bool step_until_new_line(const Tree& tree, Path& path, Walk& k) noexcept {
  for (;;) {
    const uintptr_t line = cache_line(tree.along_next(k));
    if (!tree.along_step(path, k)) return false;
    const void* next = tree.along_next(k);
    if (cache_line(next) != line) {
      __builtin_prefetch(next);
      return true;
    }
  }
}

}  // namespace st
