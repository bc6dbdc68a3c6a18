#pragma once
/// \file SceneLoadCache.h
/// What the object readers of one scene-file load share (ObjectSpecContext::cache): the files
/// they request, read once each and in parallel before any build, objects shared between entries
/// with the same source, and the load's counts.

#include "duplex/accel/Error.h"
#include "duplex/accel/Object.h"

#include <atomic>
#include <cstddef>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <typeindex>
#include <typeinfo>
#include <utility>

namespace duplex {

/// State shared by the object readers of one scene-file load, kept alive by the factories that use
/// it. Thread-safe.
class SceneLoadCache {
 public:
  /// Reads one file for a type (a mesh file, ...) into a value of type T (never null). May call
  /// `cache`.addCount() (warnings found, ...). Throws on failure; the message names the file. Runs
  /// isolated from the caller's other TBB work (it may use TBB itself).
  template <class T>
  using FileReader = std::function<std::shared_ptr<const T>(const std::filesystem::path& file, SceneLoadCache& cache)>;

  /// Registers `file` (a resolved path) to be read by `reader` under `kind`; readers call it while the
  /// scene file is parsed, so that the files are read in parallel by readRequested(), once per (kind,
  /// file) however the path is spelt, before any build. `kind` is the type's own name ("mesh"): a
  /// (kind, file) pair holds one value type, and a request with another T throws InvalidArgument. The
  /// first request's reader and spelling are kept.
  template <class T>
  void requestFile(std::string_view kind, const std::filesystem::path& file, FileReader<T> reader) {
    if (!reader) throw InvalidArgument("SceneLoadCache::requestFile: no reader for " + file.string());
    request(kind, file, typeid(T), [reader = std::move(reader)](const std::filesystem::path& f, SceneLoadCache& cache) {
      return std::shared_ptr<const void>(reader(f, cache));
    });
  }
  /// Reads every requested file not read yet, in parallel (TBB). Errors are kept and thrown by file().
  void readRequested();
  /// The value read from `file` under `kind` (now, if it was not read before). Throws the reader's
  /// error as FileError; InvalidArgument when the file was never requested under `kind`, or was
  /// requested with another value type than T.
  template <class T>
  [[nodiscard]] std::shared_ptr<const T> file(std::string_view kind, const std::filesystem::path& file) {
    return std::static_pointer_cast<const T>(fileValue(kind, file, typeid(T)));
  }
  /// The key under which a file is cached and objects of one source are shared: its weakly canonical
  /// path (the path as given when that fails), so that "a/../b.obj" and "./b.obj" are one file.
  [[nodiscard]] static std::filesystem::path fileKey(const std::filesystem::path& file);
  /// The object stored under `key`, built by `build` on the first call for that key (concurrent
  /// callers wait; the build runs isolated from their TBB work, so nested parallel builds cannot
  /// deadlock). Objects of several entries with the same source (mesh file, prepared structure)
  /// are built once and shared this way. A build that throws is retried by the next call.
  [[nodiscard]] std::shared_ptr<const Object> shared(const std::string& key,
                                                     const std::function<std::shared_ptr<const Object>()>& build);

  /// Adds `n` to the load's count `name` (summed over files and objects, reported in
  /// SceneLoadFigures::counts).
  void addCount(std::string_view name, std::size_t n);
  /// The counts added, and "<kind>_files" for each kind requested: its number of distinct files.
  [[nodiscard]] std::map<std::string, std::size_t, std::less<>> counts() const;
  /// Prepared structures read instead of built: a type's reader counts each one it loads.
  std::atomic<std::size_t> structures_loaded{0};

 private:
  using ErasedReader =
      std::function<std::shared_ptr<const void>(const std::filesystem::path& file, SceneLoadCache& cache)>;
  struct FileEntry {
    std::filesystem::path file;  // as first requested (messages name it)
    std::type_index type = typeid(void);
    ErasedReader reader;
    std::once_flag once;
    std::shared_ptr<const void> value;
    std::string error;
  };
  struct SharedEntry {
    std::mutex mutex;
    std::shared_ptr<const Object> object;
  };
  void request(std::string_view kind, const std::filesystem::path& file, std::type_index type, ErasedReader reader);
  FileEntry* findEntry(std::string_view kind, const std::filesystem::path& file);
  [[nodiscard]] std::shared_ptr<const void> fileValue(std::string_view kind, const std::filesystem::path& file,
                                                      std::type_index type);
  [[nodiscard]] std::shared_ptr<const void> read(FileEntry& entry);
  mutable std::mutex mutex_;  // guards the maps (entries never move: held by unique_ptr)
  // by kind, then canonical path
  std::map<std::pair<std::string, std::filesystem::path>, std::unique_ptr<FileEntry>> files_;
  std::map<std::string, std::unique_ptr<SharedEntry>> shared_;
  std::map<std::string, std::size_t, std::less<>> counts_;
};

}  // namespace duplex
