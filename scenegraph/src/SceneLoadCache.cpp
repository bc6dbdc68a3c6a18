#include "duplex/scenegraph/SceneLoadCache.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/MemoryLimit.h"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <mutex>
#include <unordered_set>

namespace duplex {

std::filesystem::path SceneLoadCache::fileKey(const std::filesystem::path& file) {
  std::error_code ec;
  std::filesystem::path key = std::filesystem::weakly_canonical(file, ec);
  return ec || key.empty() ? file : key;
}

SceneLoadCache::FileEntry* SceneLoadCache::findEntry(std::string_view kind, const std::filesystem::path& file) {
  const std::pair<std::string, std::filesystem::path> key(std::string(kind), fileKey(file));
  std::lock_guard lock(mutex_);
  const auto it = files_.find(key);
  return it == files_.end() ? nullptr : it->second.get();
}

void SceneLoadCache::request(std::string_view kind, const std::filesystem::path& file, std::type_index type,
                             ErasedReader reader) {
  std::pair<std::string, std::filesystem::path> key(std::string(kind), fileKey(file));
  std::lock_guard lock(mutex_);
  auto& slot = files_[std::move(key)];
  if (!slot) {
    slot = std::make_unique<FileEntry>();
    slot->file = file;
    slot->type = type;
    slot->reader = std::move(reader);
  } else if (slot->type != type) {
    throw InvalidArgument("SceneLoadCache: " + file.string() + " is requested as a " + std::string(kind) +
                          " file with two value types");
  }
}

namespace {

// The entries whose reader failed for want of memory (a ResourceError), so that the objects that
// need the file see that error, not a FileError. Kept beside the entries (their layout is
// public); an entry clears its own mark before it reads, so a later entry at the same address
// never inherits one.
std::mutex g_resource_mutex;
std::unordered_set<const void*> g_resource_failures;

void markResourceFailure(const void* entry, bool failed) {
  std::lock_guard lock(g_resource_mutex);
  if (failed) g_resource_failures.insert(entry);
  else g_resource_failures.erase(entry);
}

bool isResourceFailure(const void* entry) {
  std::lock_guard lock(g_resource_mutex);
  return g_resource_failures.count(entry) != 0;
}

}  // namespace

std::shared_ptr<const void> SceneLoadCache::read(FileEntry& e) {
  std::call_once(e.once, [&] {
    markResourceFailure(&e, false);
    try {
      // Isolated: a reader that runs TBB work must not pick up, while it waits, a task that waits for
      // this same once-flag.
      tbb::this_task_arena::isolate([&] { e.value = e.reader(e.file, *this); });
      if (!e.value) e.error = e.file.string() + ": the reader returned nothing";
    } catch (const ResourceError& ex) {
      e.error = ex.what();
      markResourceFailure(&e, true);
    } catch (const std::exception& ex) {
      e.error = ex.what();
    } catch (...) {
      e.error = e.file.string() + ": unknown error while reading";
    }
  });
  if (!e.value) {
    if (isResourceFailure(&e)) throw ResourceError(e.error);
    throw FileError(e.error);
  }
  return e.value;
}

std::shared_ptr<const void> SceneLoadCache::fileValue(std::string_view kind, const std::filesystem::path& file,
                                                      std::type_index type) {
  FileEntry* e = findEntry(kind, file);
  if (!e)
    throw InvalidArgument("SceneLoadCache::file: " + file.string() + " was not requested as a " + std::string(kind) +
                          " file");
  if (e->type != type)
    throw InvalidArgument("SceneLoadCache::file: " + file.string() + " holds a " + std::string(kind) +
                          " value of another type");
  return read(*e);
}

void SceneLoadCache::readRequested() {
  std::vector<FileEntry*> entries;
  {
    std::lock_guard lock(mutex_);
    for (const auto& [key, entry] : files_) entries.push_back(entry.get());
  }
  tbb::parallel_for(std::size_t{0}, entries.size(), [&](std::size_t i) {
    try {
      (void)read(*entries[i]);
    } catch (const std::exception&) {
      // kept in the entry; thrown to the object that needs the file
    }
  });
}

std::shared_ptr<const Object> SceneLoadCache::shared(const std::string& key,
                                                     const std::function<std::shared_ptr<const Object>()>& build) {
  SharedEntry* e;
  {
    std::lock_guard lock(mutex_);
    auto& slot = shared_[key];
    if (!slot) slot = std::make_unique<SharedEntry>();
    e = slot.get();
  }
  std::lock_guard lock(e->mutex);
  // Isolated: while this thread waits inside the build's parallel work it must not pick up another
  // object's task that waits for this same mutex.
  if (!e->object) tbb::this_task_arena::isolate([&] { e->object = build(); });
  return e->object;
}

void SceneLoadCache::addCount(std::string_view name, std::size_t n) {
  std::lock_guard lock(mutex_);
  auto it = counts_.find(name);
  if (it == counts_.end()) it = counts_.emplace(std::string(name), 0).first;
  it->second += n;
}

std::map<std::string, std::size_t, std::less<>> SceneLoadCache::counts() const {
  std::lock_guard lock(mutex_);
  auto out = counts_;
  for (const auto& [key, entry] : files_) ++out[key.first + "_files"];
  return out;
}

}  // namespace duplex
