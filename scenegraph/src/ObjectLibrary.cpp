/// \file ObjectLibrary.cpp
/// Entries live in a deque (they hold a mutex and never move). A deferred entry is built under its
/// own mutex with double-checked locking on an atomic flag, so concurrent get() calls of one object
/// wait for a single factory call while get() calls of other objects proceed in parallel.

#include "duplex/scenegraph/ObjectLibrary.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/Log.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <exception>
#include <string>
#include <utility>
#include <vector>

namespace duplex {

ObjectId ObjectLibrary::add(std::string name, std::shared_ptr<const Object> object) {
  if (!object) throw InvalidArgument("ObjectLibrary::add: object '" + name + "' is null");
  std::string type_name(object->typeName());
  return push(std::move(name), std::move(type_name), nullptr, std::move(object));
}

ObjectId ObjectLibrary::addDeferred(std::string name, std::string type_name, Factory factory) {
  if (!factory) throw InvalidArgument("ObjectLibrary::addDeferred: object '" + name + "' has no factory");
  return push(std::move(name), std::move(type_name), std::move(factory), nullptr);
}

ObjectId ObjectLibrary::push(std::string name, std::string type_name, Factory factory,
                             std::shared_ptr<const Object> object) {
  // Validate everything before touching the containers, so a rejected add changes nothing.
  if (name.empty()) throw InvalidArgument("ObjectLibrary: an object needs a non-empty name");
  if (by_name_.count(name) != 0) throw InvalidArgument("ObjectLibrary: duplicate object name '" + name + "'");
  if (entries_.size() >= kInvalidObject) throw InvalidArgument("ObjectLibrary: too many objects");
  const auto id = static_cast<ObjectId>(entries_.size());
  Entry& e = entries_.emplace_back();  // may throw; nothing changed yet
  try {
    by_name_.emplace(name, id);
  } catch (...) {
    entries_.pop_back();
    throw;
  }
  e.name = std::move(name);
  e.type_name = std::move(type_name);
  e.factory = std::move(factory);
  e.object = std::move(object);
  e.built.store(e.object != nullptr, std::memory_order_release);
  return id;
}

std::optional<ObjectId> ObjectLibrary::find(std::string_view name) const {
  const auto it = by_name_.find(std::string(name));
  if (it == by_name_.end()) return std::nullopt;
  return it->second;
}

const ObjectLibrary::Entry& ObjectLibrary::entry(ObjectId id) const {
  if (id >= entries_.size())
    throw InvalidArgument("ObjectLibrary: unknown object id " + std::to_string(id) + " (library holds " +
                          std::to_string(entries_.size()) + " objects)");
  return entries_[id];
}

const ObjectLibrary::Entry& ObjectLibrary::liveEntry(ObjectId id, const char* call) const {
  const Entry& e = entry(id);
  if (e.removed)
    throw InvalidArgument(std::string("ObjectLibrary::") + call + ": object '" + e.name + "' (id " +
                          std::to_string(id) + ") was removed");
  return e;
}

const std::string& ObjectLibrary::name(ObjectId id) const { return entry(id).name; }
const std::string& ObjectLibrary::typeName(ObjectId id) const { return entry(id).type_name; }
bool ObjectLibrary::isBuilt(ObjectId id) const {
  return liveEntry(id, "isBuilt").built.load(std::memory_order_acquire);
}

void ObjectLibrary::replace(ObjectId id, std::shared_ptr<const Object> object) {
  const Entry& c = liveEntry(id, "replace");
  if (!object) throw InvalidArgument("ObjectLibrary::replace: null object for '" + c.name + "'");
  Entry& e = entries_[id];
  std::string type_name(object->typeName());  // may throw: before anything changes
  std::lock_guard lock(e.mutex);
  e.type_name = std::move(type_name);
  e.object = std::move(object);
  e.factory = nullptr;
  e.built.store(true, std::memory_order_release);
}

void ObjectLibrary::remove(ObjectId id) {
  (void)liveEntry(id, "remove");
  Entry& e = entries_[id];
  std::lock_guard lock(e.mutex);
  by_name_.erase(e.name);
  e.object.reset();
  e.factory = nullptr;
  e.removed = true;
  ++removed_;
}

std::size_t ObjectLibrary::memoryBytes(ObjectId id) const {
  const Entry& e = liveEntry(id, "memoryBytes");
  return e.built.load(std::memory_order_acquire) ? e.object->memoryBytes() : 0;
}

std::size_t ObjectLibrary::memoryBytes() const {
  std::size_t total = 0;
  for (const Entry& e : entries_)
    if (!e.removed && e.built.load(std::memory_order_acquire)) total += e.object->memoryBytes();
  return total;
}

std::shared_ptr<const Object> ObjectLibrary::runFactory(const Entry& e) const {
  std::shared_ptr<const Object> object;
  try {
    object = e.factory();
  } catch (const std::exception& ex) {
    throw InvalidArgument("object '" + e.name + "' (type " + e.type_name + "): build failed: " + ex.what());
  } catch (...) {
    throw InvalidArgument("object '" + e.name + "' (type " + e.type_name + "): build failed (unknown error)");
  }
  if (!object) throw InvalidArgument("object '" + e.name + "' (type " + e.type_name + "): factory returned null");
  return object;
}

void ObjectLibrary::install(const Entry& e, std::shared_ptr<const Object> object) const {
  e.object = std::move(object);
  e.factory = nullptr;  // release what the factory captured (source meshes, file names)
  e.built.store(true, std::memory_order_release);
  build_count_.fetch_add(1);
  logger()->debug("object '{}' built ({} bytes)", e.name, e.object->memoryBytes());
}

std::shared_ptr<const Object> ObjectLibrary::get(ObjectId id) const {
  const Entry& e = liveEntry(id, "get");
  // Fast path: once built, `object` is only written again by replace() (which must not overlap).
  if (e.built.load(std::memory_order_acquire)) return e.object;
  std::lock_guard lock(e.mutex);
  if (e.built.load(std::memory_order_relaxed)) return e.object;
  install(e, runFactory(e));
  return e.object;
}

void ObjectLibrary::buildAll(std::span<const ObjectId> ids, const WorkControl& control) const {
  for (const ObjectId id : ids) (void)liveEntry(id, "buildAll");  // bad ids throw before any build
  // Built into `made` first and installed only when every build ran, so that a cancelled call
  // leaves the library as it was. One slot per listed id, so that "the first failure" is the
  // first in list order, whatever the timing.
  std::vector<std::shared_ptr<const Object>> made(ids.size());
  std::vector<std::exception_ptr> failures(ids.size());
  ProgressCounter counter(control, ids.size());
  std::atomic<bool> stopped{false};
  tbb::parallel_for(std::size_t{0}, ids.size(), [&](std::size_t i) {
    if (stopped.load(std::memory_order_relaxed) || control.cancelled()) {
      stopped.store(true, std::memory_order_relaxed);
      return;
    }
    const Entry& e = entries_[ids[i]];
    if (!e.built.load(std::memory_order_acquire)) {
      std::lock_guard lock(e.mutex);  // one factory call at a time per object, as get() makes it
      if (!e.built.load(std::memory_order_relaxed)) {
        try {
          made[i] = runFactory(e);
        } catch (...) {
          failures[i] = std::current_exception();
        }
      }
    }
    counter.add(1);
  });
  if (stopped.load() || control.cancelled())
    throw Cancelled(
        "ObjectLibrary::buildAll: cancelled after " +
        std::to_string(std::count_if(made.begin(), made.end(), [](const auto& m) { return m != nullptr; })) + " of " +
        std::to_string(ids.size()) + " builds; none was kept");
  for (std::size_t i = 0; i < ids.size(); ++i) {
    if (!made[i]) continue;
    const Entry& e = entries_[ids[i]];
    std::lock_guard lock(e.mutex);
    if (!e.built.load(std::memory_order_relaxed)) install(e, std::move(made[i]));
  }
  for (const auto& f : failures)
    if (f) std::rethrow_exception(f);
}

void ObjectLibrary::buildAll(const WorkControl& control) const {
  std::vector<ObjectId> pending;
  for (std::size_t i = 0; i < entries_.size(); ++i)
    if (!entries_[i].removed && !entries_[i].built.load(std::memory_order_acquire))
      pending.push_back(static_cast<ObjectId>(i));
  buildAll(pending, control);
}

}  // namespace duplex
