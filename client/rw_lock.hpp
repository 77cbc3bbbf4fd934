// A reader-writer lock that prefers writers (internal to client/). Lookups take it shared,
// so any number of threads read the cache at once; the fetcher takes it exclusive for
// O(1) bookkeeping (never across a network event, a decompression or a tile's
// validation). Writer preference keeps a stream of overlapping lookup batches from
// starving the fetcher: a waiting writer holds back new readers, so a reader waits at
// most for one writer's bookkeeping and a writer for the batches already running.
// Not recursive: a thread holding it shared must not take it again.
#pragma once
#include <pthread.h>

#include "common/error.hpp"

namespace st::client {

class RwLock {
 public:
  // st::Error if the system has no room for one more lock.
  RwLock() {
    pthread_rwlockattr_t attr;
    pthread_rwlockattr_init(&attr);
    pthread_rwlockattr_setkind_np(&attr, PTHREAD_RWLOCK_PREFER_WRITER_NONRECURSIVE_NP);
    const int rc = pthread_rwlock_init(&lock_, &attr);
    pthread_rwlockattr_destroy(&attr);
    if (rc != 0) throw Error("client: cannot create a reader-writer lock");
  }
  ~RwLock() { pthread_rwlock_destroy(&lock_); }
  RwLock(const RwLock&) = delete;
  RwLock& operator=(const RwLock&) = delete;

  void lock() noexcept { pthread_rwlock_wrlock(&lock_); }
  void unlock() noexcept { pthread_rwlock_unlock(&lock_); }
  void lock_shared() noexcept { pthread_rwlock_rdlock(&lock_); }
  void unlock_shared() noexcept { pthread_rwlock_unlock(&lock_); }

 private:
  pthread_rwlock_t lock_;
};

}  // namespace st::client
