#pragma once
/// \file SlotTable.h
/// Records addressed by ids that are handed out once and never reused, stored in slots that are.
///
/// Why: a scene graph edited for hours (a CAD session adding and removing parts) hands out ids
/// without bound, and callers may hold ids of removed nodes, so an id must never name a new node.
/// A record is large (two double transforms, a name), an id-to-slot entry is 4 bytes: a released
/// record's slot takes the next new record, and only its 4-byte entry stays behind.

#include <cstdint>
#include <utility>
#include <vector>

namespace duplex {

template <class T>
class SlotTable {
 public:
  static constexpr std::uint32_t kNoSlot = 0xFFFFFFFFu;

  /// Ids handed out so far (the next push gets this id).
  [[nodiscard]] std::size_t idCount() const { return slot_of_id_.size(); }
  /// Slots held (records in use plus free slots awaiting reuse).
  [[nodiscard]] std::size_t slotCount() const { return records_.size(); }
  /// Whether `id` was handed out and its record not released.
  [[nodiscard]] bool has(std::uint32_t id) const { return id < slot_of_id_.size() && slot_of_id_[id] != kNoSlot; }

  /// The record of `id`; `id` must satisfy has().
  T& operator[](std::uint32_t id) { return records_[slot_of_id_[id]]; }
  const T& operator[](std::uint32_t id) const { return records_[slot_of_id_[id]]; }

  /// Makes the next push() unable to throw (growing geometrically).
  void reserveOneMore() {
    grow(slot_of_id_);
    if (free_.empty()) {
      grow(records_);
      grow(id_of_slot_);
    }
  }

  /// Stores `record` under the next id (in a free slot when there is one) and returns the id.
  /// Cannot throw after reserveOneMore().
  std::uint32_t push(T&& record) {
    const auto id = static_cast<std::uint32_t>(slot_of_id_.size());
    std::uint32_t slot;
    if (!free_.empty()) {
      slot = free_.back();
      free_.pop_back();
      records_[slot] = std::move(record);
      id_of_slot_[slot] = id;
    } else {
      slot = static_cast<std::uint32_t>(records_.size());
      records_.push_back(std::move(record));
      id_of_slot_.push_back(id);
    }
    slot_of_id_.push_back(slot);
    return id;
  }

  /// Undoes the last push() (its id will be handed out again): for an insertion that failed later.
  void popLast() noexcept {
    const std::uint32_t slot = slot_of_id_.back();
    slot_of_id_.pop_back();
    if (slot + 1 == records_.size()) {
      records_.pop_back();
      id_of_slot_.pop_back();
    } else {
      release(slot);
    }
  }

  /// Frees the record of `id` (which must satisfy has()): its memory is returned, its slot reused
  /// by a later push(), and has(id) is false from now on.
  void releaseId(std::uint32_t id) noexcept {
    const std::uint32_t slot = slot_of_id_[id];
    slot_of_id_[id] = kNoSlot;
    release(slot);
  }

  /// Calls f(id, record) for every record in use, in slot order (not id order).
  template <class F>
  void forEach(F&& f) const {
    for (std::size_t s = 0; s < records_.size(); ++s)
      if (id_of_slot_[s] != kNoSlot) f(id_of_slot_[s], records_[s]);
  }

 private:
  template <class V>
  static void grow(V& v) {
    if (v.size() == v.capacity()) v.reserve(2 * v.size() + 16);
  }
  void release(std::uint32_t slot) noexcept {
    records_[slot] = T{};  // returns heap memory the record owns (its name)
    id_of_slot_[slot] = kNoSlot;
    try {
      free_.push_back(slot);
    } catch (...) {
      // Out of memory: the slot is only lost for reuse; the table stays consistent.
    }
  }

  std::vector<T> records_;
  std::vector<std::uint32_t> id_of_slot_;  // kNoSlot for a free slot
  std::vector<std::uint32_t> slot_of_id_;  // kNoSlot for a released id
  std::vector<std::uint32_t> free_;
};

}  // namespace duplex
