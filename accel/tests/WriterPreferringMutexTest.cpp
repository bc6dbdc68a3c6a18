// WriterPreferringMutex: mutual exclusion under a mix of readers and writers, and a waiting
// writer getting in while readers keep overlapping (which glibc's std::shared_mutex does not
// guarantee: there the writer can wait for as long as the readers keep coming).

#include "duplex/accel/WriterPreferringMutex.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <mutex>
#include <shared_mutex>
#include <thread>
#include <vector>

namespace duplex {
namespace {

TEST(WriterPreferringMutex, ReadersShareWritersExclude) {
  WriterPreferringMutex mutex;
  std::atomic<int> readers{0}, writers{0}, max_readers{0};
  std::atomic<long> violations{0};
  long plain = 0;  // written only under the exclusive lock
  std::vector<std::thread> threads;
  for (int t = 0; t < 6; ++t) {
    threads.emplace_back([&, t] {
      for (int i = 0; i < 3000; ++i) {
        if ((i + t) % 5 == 0) {
          std::unique_lock lock(mutex);
          if (writers.fetch_add(1) != 0 || readers.load() != 0) ++violations;
          ++plain;
          writers.fetch_sub(1);
        } else {
          std::shared_lock lock(mutex);
          const int now = readers.fetch_add(1) + 1;
          int seen = max_readers.load();
          while (now > seen && !max_readers.compare_exchange_weak(seen, now)) {
          }
          if (writers.load() != 0) ++violations;
          readers.fetch_sub(1);
        }
      }
    });
  }
  for (std::thread& t : threads) t.join();
  EXPECT_EQ(violations.load(), 0);
  EXPECT_EQ(plain, 6 * 3000 / 5);
  EXPECT_EQ(readers.load(), 0);
  EXPECT_EQ(writers.load(), 0);
}

TEST(WriterPreferringMutex, AWaitingWriterKeepsNewReadersOut) {
  WriterPreferringMutex mutex;
  constexpr int kReaders = 3;
  std::atomic<bool> stop{false};
  std::atomic<long> acquired{0};
  std::vector<std::thread> readers;
  // Readers overlap: each holds its shared lock for a while, so there is nearly always one inside.
  for (int t = 0; t < kReaders; ++t) {
    readers.emplace_back([&] {
      while (!stop.load()) {
        std::shared_lock lock(mutex);
        acquired.fetch_add(1);
        std::this_thread::sleep_for(std::chrono::microseconds(200));
      }
    });
  }
  while (acquired.load() < 50) std::this_thread::yield();
  for (int round = 0; round < 20; ++round) {
    const long before = acquired.load();
    {
      std::unique_lock lock(mutex);
      // Only readers that were already past the writer's announcement can have got in meanwhile.
      EXPECT_LE(acquired.load() - before, kReaders) << "round " << round;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  stop.store(true);
  for (std::thread& t : readers) t.join();
}

}  // namespace
}  // namespace duplex
