#pragma once
/// \file WorkControl.h
/// Progress reports and cancellation for long library work (scene loads, bottom-level builds,
/// batch queries): the caller passes a WorkControl; the work reports (done, total) through
/// `progress` and stops with Cancelled once `cancel` is set, leaving what it was changing as it was.

#include "duplex/accel/Error.h"

#include <atomic>
#include <cstddef>
#include <functional>
#include <mutex>

namespace duplex {

/// Set from any thread (a UI button, a signal handler's flag, the progress callback) to stop the
/// work that watches it.
class CancelToken {
 public:
  /// Asks the work to stop; it stops at its next check (between objects, between chunks of rays).
  void cancel() { flag_.store(true, std::memory_order_relaxed); }
  /// Whether cancel() was called (and not reset()).
  [[nodiscard]] bool cancelled() const { return flag_.load(std::memory_order_relaxed); }
  /// Clears the request, so that the token can serve the next piece of work.
  void reset() { flag_.store(false, std::memory_order_relaxed); }

 private:
  std::atomic<bool> flag_{false};
};

/// Thrown by work that was cancelled. Not a bad-input Error: nothing was wrong with the input.
class Cancelled : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// What a caller gives long work. Both parts are optional (the default reports nothing and never
/// stops). `progress(done, total)` is called with done increasing to total, one call at a time
/// (the work serialises the calls), from any of the work's threads; `total` is the work's own unit
/// (objects built, rays traced) and stays the same through one piece of work.
struct WorkControl {
  std::function<void(std::size_t done, std::size_t total)> progress;  ///< called as work completes; may be empty
  const CancelToken* cancel = nullptr;                                ///< watched between steps; may be null

  /// Whether the work should stop now.
  [[nodiscard]] bool cancelled() const { return cancel != nullptr && cancel->cancelled(); }
};

/// A WorkControl's progress, counted from many threads: add(n) after n units of work.
class ProgressCounter {
 public:
  /// Counts toward `total` units for `control` (which must outlive the counter).
  ProgressCounter(const WorkControl& control, std::size_t total) : control_(control), total_(total) {}
  /// Adds n done units and reports the new count.
  void add(std::size_t n) {
    if (!control_.progress) return;
    std::lock_guard lock(mutex_);
    done_ += n;
    control_.progress(done_, total_);
  }

 private:
  const WorkControl& control_;
  std::size_t total_;
  std::size_t done_ = 0;
  std::mutex mutex_;
};

}  // namespace duplex
