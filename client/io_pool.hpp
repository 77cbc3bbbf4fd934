// A few I/O threads shared by many Clients (the load tester's 1,000 connections).
//
// By default every Client runs its fetcher on a thread of its own (one io_context, one
// thread: fetcher.hpp). A process that opens hundreds of connections would then hold
// hundreds of threads, epoll sets and timer fds. With ClientOptions::io_pool set, the
// fetcher runs on one of the pool's io_contexts instead (round-robin). Each io_context
// is run by exactly one thread, so a fetcher's session state still needs no locks.
//
//   auto pool = std::make_shared<st::client::IoPool>(2);
//   st::client::ClientOptions o;
//   o.io_pool = pool;  // every Client made with `o` shares the pool's 2 threads
//
// The pool outlives every Client using it (they hold a shared_ptr). Its destructor stops
// and joins the threads; destroy the Clients first (a Client's destructor waits until its
// fetcher's coroutines and posted handlers have finished on the pool's thread).
#pragma once
#include <atomic>
#include <memory>
#include <thread>
#include <vector>

#include "net/asio.hpp"

#include <boost/asio/executor_work_guard.hpp>
#include <boost/asio/io_context.hpp>

namespace st::client {

class IoPool {
 public:
  // threads in [1, 64]; st::Error otherwise.
  explicit IoPool(unsigned threads = 1);
  ~IoPool();
  IoPool(const IoPool&) = delete;
  IoPool& operator=(const IoPool&) = delete;

  unsigned threads() const noexcept { return unsigned(contexts_.size()); }
  // The io_context of the next fetcher (round-robin); runs on one thread only.
  boost::asio::io_context& next() noexcept;

 private:
  using Guard = boost::asio::executor_work_guard<boost::asio::io_context::executor_type>;
  std::vector<std::unique_ptr<boost::asio::io_context>> contexts_;
  std::vector<Guard> guards_;  // keep run() going while no fetcher has work queued
  std::vector<std::thread> threads_;
  std::atomic<uint64_t> next_{0};
};

}  // namespace st::client
