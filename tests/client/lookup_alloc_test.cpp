// Lookups never allocate (client.hpp's contract): counts this thread's operator new calls
// around lookups that miss (queueing fetches) and lookups that hit, for every encoding.
#include <gtest/gtest.h>

#include <cstdlib>
#include <new>

#include "client/map_access.hpp"
#include "tests/client/loopback.hpp"

namespace {
thread_local uint64_t t_allocations = 0;
// The probe's pointer goes here, so no optimisation level may elide its allocations
// (new-expressions whose result is unused may be removed since C++14).
void* volatile g_probe_escape = nullptr;
}  // namespace

// Counting replacements of the global allocation functions (the whole test binary uses
// them; they only count, per thread, and forward to malloc). g++ sees new -> malloc and
// delete -> free inlined into callers and calls that "mismatched": it is the point here.
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
void* operator new(std::size_t n) {
  ++t_allocations;
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n) {
  ++t_allocations;
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
// The nothrow forms too (libraries in this binary call them, then the deletes below).
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  ++t_allocations;
  return std::malloc(n ? n : 1);
}
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept {
  ++t_allocations;
  return std::malloc(n ? n : 1);
}
void operator delete(void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }

namespace st::client {
namespace {

using namespace std::chrono_literals;

TEST(RemoteMapLookups, NeverAllocateWhetherTilesAreMissingOrResident) {
  {  // the probe itself counts
    const uint64_t before = t_allocations;
    auto* v = new std::vector<int>(10);
    g_probe_escape = v->data();
    g_probe_escape = v;
    delete v;
    ASSERT_EQ(t_allocations, before + 2);
  }
  for (Encoding e : looptest::available_encodings()) {
    SCOPED_TRACE(to_string(e));
    const uint32_t level = 6, side = 1u << level;
    auto p = looptest::build_pack("alloc_" + to_string(e), level, 17, e, 3, 512);
    auto srv = looptest::start_server({p.path});
    ClientOptions o;
    o.cache_slots = uint32_t(p.reader->tiles().size()) + 4;
    Client client({"127.0.0.1", srv.port}, o);
    Map map = client.open("alloc_" + to_string(e));
    const Evaluator& ev = client::evaluator(map);
    float sink = 0;
    auto sweep = [&] {
      for (uint32_t l = 0; l <= level; ++l)
        for (uint64_t y = 0; y < (uint64_t(1) << l); ++y)
          for (uint64_t x = 0; x < (uint64_t(1) << l); ++x) sink += ev.depth(l, x, y);
      for (uint64_t i = 0; i < 64; ++i) sink += map.pcf(level, i, 63 - i, 5, 0.5f) + map.visibility({0.1 * double(i), 1, 0}, 5);
    };
    const uint64_t before_miss = t_allocations;
    sweep();  // nothing resident: coarse answers, fetches queued
    EXPECT_EQ(t_allocations, before_miss) << "lookups that miss allocated";
    map.request_region(level, 0, 0, side, side, 1);
    ASSERT_TRUE(looptest::wait_until([&] { return map.region_resident(level, 0, 0, side, side); }));
    const uint64_t before_hit = t_allocations;
    sweep();
    EXPECT_EQ(t_allocations, before_hit) << "lookups that hit allocated";
    EXPECT_NE(sink, -1.0f);
  }
}

}  // namespace
}  // namespace st::client
