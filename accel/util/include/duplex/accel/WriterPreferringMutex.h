#pragma once
/// \file WriterPreferringMutex.h
/// A reader-writer lock under which a waiting writer goes first: once lock() is waiting, no new
/// shared owner gets in, so the writer waits only for the shared owners already inside. Meets the
/// standard SharedMutex requirements used by std::shared_lock and std::unique_lock (lock,
/// unlock, lock_shared, unlock_shared). glibc's std::shared_mutex prefers readers instead: with
/// overlapping readers a writer can wait for ever.
///
/// Costs: lock_shared() and unlock_shared() are one atomic read-modify-write each when no writer
/// waits, like std::shared_mutex; waiting uses std::atomic::wait (a futex on Linux). Not
/// recursive: a thread that holds a shared lock and asks for another one deadlocks as soon as a
/// writer waits between the two.

#include <atomic>
#include <cstdint>
#include <mutex>

namespace duplex {

/// See the file comment.
class WriterPreferringMutex {
 public:
  WriterPreferringMutex() = default;
  WriterPreferringMutex(const WriterPreferringMutex&) = delete;
  WriterPreferringMutex& operator=(const WriterPreferringMutex&) = delete;

  /// Shared ownership; waits while a writer holds or waits for the lock.
  void lock_shared() {
    std::uint32_t s = state_.load(std::memory_order_relaxed);
    for (;;) {
      if ((s & (kWriter | kWaiting)) == 0) {
        if (state_.compare_exchange_weak(s, s + 1, std::memory_order_acquire, std::memory_order_relaxed)) return;
        continue;  // s holds the current state
      }
      state_.wait(s, std::memory_order_relaxed);
      s = state_.load(std::memory_order_relaxed);
    }
  }
  /// Ends shared ownership; the last shared owner wakes a waiting writer.
  void unlock_shared() {
    const std::uint32_t before = state_.fetch_sub(1, std::memory_order_release);
    if ((before & kWaiting) != 0 && (before & kReaders) == 1) state_.notify_all();
  }
  /// Exclusive ownership: announces itself (new shared owners wait from now on), then waits for
  /// the shared owners inside to leave. Writers are served one at a time.
  void lock() {
    writers_.lock();
    std::uint32_t s = state_.fetch_or(kWaiting, std::memory_order_relaxed) | kWaiting;
    for (;;) {
      if ((s & kReaders) == 0) {
        if (state_.compare_exchange_weak(s, kWriter, std::memory_order_acquire, std::memory_order_relaxed)) return;
        continue;
      }
      state_.wait(s, std::memory_order_relaxed);
      s = state_.load(std::memory_order_relaxed);
    }
  }
  /// Ends exclusive ownership and wakes everyone waiting.
  void unlock() {
    state_.store(0, std::memory_order_release);
    state_.notify_all();
    writers_.unlock();
  }

 private:
  static constexpr std::uint32_t kWriter = 1u << 31;   // a writer holds the lock
  static constexpr std::uint32_t kWaiting = 1u << 30;  // a writer waits for the shared owners to leave
  static constexpr std::uint32_t kReaders = kWaiting - 1;
  std::atomic<std::uint32_t> state_{0};  // kWriter | kWaiting | number of shared owners
  std::mutex writers_;                   // one writer at a time
};

}  // namespace duplex
