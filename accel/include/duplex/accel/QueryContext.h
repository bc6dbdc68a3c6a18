#pragma once
/// \file QueryContext.h
/// Per-thread mutable state for queries. Acceleration structures and objects are immutable after
/// build; anything a query must mutate (counters, caches such as OpenVDB accessors, scratch
/// buffers) lives here, one context per thread.

#include <cstdint>
#include <memory>
#include <typeinfo>
#include <utility>
#include <vector>

namespace duplex {

/// Counters a test or benchmark can read. Plain integers: a context belongs to one thread.
struct QueryStats {
  std::uint64_t rays = 0;             ///< rays queried with this context
  std::uint64_t instance_visits = 0;  ///< top-level leaf tests that reached an object
  /// Crossing queries: plane tests that settled a flat sensor whose box the ray met as plainly
  /// missed, without asking the object. The mailbox runs first, so a sensor the walk lists in
  /// several cells or leaves is tested once per query (while the 8-entry mailbox holds it).
  std::uint64_t crossing_plane_misses = 0;
};

/// One per thread; cheap to create (no allocation until an object caches something). Not
/// thread-safe by design.
class QueryContext {
 public:
  QueryStats stats;  ///< counters of the queries run with this context

  QueryContext() = default;
  /// A copy takes the counters only: cached per-thread state is never shared between contexts.
  QueryContext(const QueryContext& other) : stats(other.stats) {}
  /// Takes the counters only, like the copy constructor; the cached state stays.
  QueryContext& operator=(const QueryContext& other) {
    stats = other.stats;
    return *this;
  }
  /// Moves the counters and the cached state.
  QueryContext(QueryContext&&) noexcept = default;
  /// Moves the counters and the cached state.
  QueryContext& operator=(QueryContext&&) noexcept = default;
  ~QueryContext() = default;

  /// Per-thread state that an object keeps between its queries (e.g. an OpenVDB accessor and
  /// intersector copy): the `T` stored under `key` (usually the object's address), created with
  /// `make()` (returning T) on the first call for that key and type. The reference stays valid for
  /// the context's life. Linear search over the few slots a thread uses, most recent first; no
  /// allocation after the first call.
  /// A key may be reused by a new object at the same address after the old one died: the stored
  /// T must let its owner recognise that (e.g. hold a shared_ptr to the data it reads and compare
  /// it) and be reset by the caller.
  template <class T, class Make>
  [[nodiscard]] T& cached(const void* key, Make&& make) {
    if (!slots_.empty() && slots_.back().key == key && *slots_.back().type == typeid(T))
      return *static_cast<T*>(slots_.back().value.get());
    for (std::size_t k = 0; k + 1 < slots_.size(); ++k) {
      if (slots_[k].key == key && *slots_[k].type == typeid(T)) {
        std::swap(slots_[k], slots_.back());
        return *static_cast<T*>(slots_.back().value.get());
      }
    }
    T* value = new T(std::forward<Make>(make)());
    slots_.push_back(Slot{key, &typeid(T), ErasedPtr(value, [](void* p) { delete static_cast<T*>(p); })});
    return *value;
  }
  /// Number of cached slots (for tests).
  [[nodiscard]] std::size_t cachedSlots() const { return slots_.size(); }

 private:
  using ErasedPtr = std::unique_ptr<void, void (*)(void*)>;
  struct Slot {
    const void* key;
    const std::type_info* type;
    ErasedPtr value;
  };
  std::vector<Slot> slots_;
};

}  // namespace duplex
