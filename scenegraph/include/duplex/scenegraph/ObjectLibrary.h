#pragma once
/// \file ObjectLibrary.h
/// The scene's unique objects, shared by any number of instances. Bottom-level structures are
/// built lazily: an object added with a factory is built on first use, once, however many
/// instances refer to it.

#include "duplex/accel/Object.h"
#include "duplex/accel/WorkControl.h"
#include "duplex/scenegraph/NodeId.h"

#include <atomic>
#include <cstddef>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <unordered_map>
#include <deque>

namespace duplex {

/// Thread-safe: get() and buildAll() may be called from several threads; add*(), replace() and
/// remove() must not overlap with other calls. Ids are never reused: a removed object's id stays
/// dead (get() refuses it).
class ObjectLibrary {
 public:
  /// Builds the object (its bottom-level structure included). Called at most once per entry.
  using Factory = std::function<std::shared_ptr<const Object>()>;

  /// Adds a built object under a unique, non-empty `name`. Throws InvalidArgument for an empty or
  /// duplicate name or a null object; the library is then unchanged.
  ObjectId add(std::string name, std::shared_ptr<const Object> object);
  /// Adds an object to be built on first use. `type_name` is the registered type ("mesh", ...), for
  /// messages and listings. Same errors as add().
  ObjectId addDeferred(std::string name, std::string type_name, Factory factory);

  /// Replaces the object behind `id` (built or deferred) with `object`, which may be of another
  /// type; the entry keeps its name. Instances that already hold the old object (a tracer's top
  /// level) keep it until they are updated: SceneGraph::replaceObject() does this for a graph's
  /// instances at its next commit, and is what applications call. Throws InvalidArgument for an
  /// unknown or removed id or a null object; the library is then unchanged.
  void replace(ObjectId id, std::shared_ptr<const Object> object);
  /// Removes the object: its memory is released once nothing else holds it, its name is free
  /// again, and its id stays dead. The library does not know who uses it:
  /// SceneGraph::removeObject() refuses objects its instances use. Throws InvalidArgument for an
  /// unknown or removed id.
  void remove(ObjectId id);

  /// Number of ids handed out (the bound of loops over ids), removed objects included.
  [[nodiscard]] std::size_t size() const { return entries_.size(); }
  /// Number of objects not removed, built or deferred.
  [[nodiscard]] std::size_t count() const { return entries_.size() - removed_; }
  /// Whether `id` was handed out and not removed.
  [[nodiscard]] bool contains(ObjectId id) const { return id < entries_.size() && !entries_[id].removed; }
  /// The id of the object named `name`, or nullopt.
  [[nodiscard]] std::optional<ObjectId> find(std::string_view name) const;
  /// name, typeName, isBuilt: throw InvalidArgument for an unknown id (isBuilt also for a removed
  /// one; name and typeName still answer for it, for messages).
  [[nodiscard]] const std::string& name(ObjectId id) const;
  /// The registered type name the object was added with ("mesh", ...).
  [[nodiscard]] const std::string& typeName(ObjectId id) const;
  /// Whether the object exists already (added built, or its factory ran).
  [[nodiscard]] bool isBuilt(ObjectId id) const;

  /// The object, built now if it was deferred (blocking; concurrent callers wait for one build).
  /// A factory that throws leaves the entry unbuilt and the exception is rethrown as
  /// InvalidArgument naming the object (the next get() tries again). Throws for an unknown id.
  [[nodiscard]] std::shared_ptr<const Object> get(ObjectId id) const;
  /// Builds every listed deferred object, in parallel (TBB). Throws the first failure as get() does,
  /// after the others finished (the objects that built are kept). control.progress gets (objects
  /// done, ids.size()); once control.cancel is set no further build starts and Cancelled is
  /// thrown after the running ones finished, none of this call's builds kept: the library is as
  /// it was.
  void buildAll(std::span<const ObjectId> ids, const WorkControl& control = {}) const;
  /// Builds all deferred objects (see above).
  void buildAll(const WorkControl& control = {}) const;

  /// Bytes held by the object's geometry and structure (Object::memoryBytes; 0 while deferred).
  /// Throws InvalidArgument for an unknown or removed id.
  [[nodiscard]] std::size_t memoryBytes(ObjectId id) const;
  /// Sum of memoryBytes over the built objects that are not removed (an object held under two
  /// ids counts twice).
  [[nodiscard]] std::size_t memoryBytes() const;

  /// Number of factory calls that succeeded so far (tests check "once per object").
  [[nodiscard]] std::size_t buildCount() const { return build_count_.load(); }

 private:
  struct Entry {
    std::string name;
    std::string type_name;
    mutable Factory factory;  // reset after a successful build
    mutable std::mutex mutex;
    mutable std::shared_ptr<const Object> object;
    mutable std::atomic<bool> built{false};
    bool removed = false;
  };
  ObjectId push(std::string name, std::string type_name, Factory factory, std::shared_ptr<const Object> object);
  const Entry& entry(ObjectId id) const;
  /// The entry's factory called, its errors turned into InvalidArgument naming the object.
  std::shared_ptr<const Object> runFactory(const Entry& e) const;
  /// Stores a built object in its entry (the caller holds the entry's mutex).
  void install(const Entry& e, std::shared_ptr<const Object> object) const;
  /// entry(), also refusing a removed id; `call` names the method in the message.
  const Entry& liveEntry(ObjectId id, const char* call) const;
  std::deque<Entry> entries_;  // deque: entries hold a mutex and never move
  std::unordered_map<std::string, ObjectId> by_name_;
  std::size_t removed_ = 0;
  mutable std::atomic<std::size_t> build_count_{0};
};

}  // namespace duplex
