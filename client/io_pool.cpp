#include "client/io_pool.hpp"

#include "shadowtile/client.hpp"

#include "common/error.hpp"

namespace st::client {

IoPool::IoPool(unsigned threads) {
  if (threads == 0 || threads > 64) throw Error("client: IoPool threads must be in [1, 64]");
  for (unsigned i = 0; i < threads; ++i) {
    contexts_.push_back(std::make_unique<boost::asio::io_context>(1));  // hint: one thread
    guards_.emplace_back(contexts_.back()->get_executor());
  }
  for (unsigned i = 0; i < threads; ++i)
    threads_.emplace_back([ctx = contexts_[i].get()] {
      for (;;) {
        try {
          ctx->run();
          return;  // stopped: the pool is going away
        } catch (...) {
          // A handler threw (fetchers catch their own errors; only bad_alloc gets here):
          // keep serving the other fetchers on this thread.
        }
      }
    });
}

IoPool::~IoPool() {
  for (auto& g : guards_) g.reset();
  for (auto& c : contexts_) c->stop();
  for (auto& t : threads_) t.join();
}

boost::asio::io_context& IoPool::next() noexcept {
  return *contexts_[next_.fetch_add(1, std::memory_order_relaxed) % contexts_.size()];
}

}  // namespace st::client

namespace st::client {

std::shared_ptr<IoPool> make_io_pool(unsigned threads) { return std::make_shared<IoPool>(threads); }

}  // namespace st::client
