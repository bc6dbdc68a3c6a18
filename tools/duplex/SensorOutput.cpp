#include "SensorOutput.h"

#include <duplex/accel/Error.h>
#include <duplex/accel/InputFile.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cctype>
#include <set>
#include <system_error>

namespace duplex::cli {

namespace fs = std::filesystem;

namespace {

constexpr const char* kStagingName = ".duplex-sensor-staging";
// The files a sensor writes besides its map files (listed in its JSON's "map_files").
constexpr const char* kSensorExtensions[] = {".json", ".csv", ".png", ".exr", ".ies"};

// A JSON file of an earlier run, or null when it is missing or not JSON (nothing to learn from it:
// its files are then left where they are).
nlohmann::json readJsonOrNull(const fs::path& path) {
  try {
    return nlohmann::json::parse(readWholeFile(path, "earlier sensor result"), nullptr, false);
  } catch (const Error&) {
    return nullptr;
  }
}

// The files the earlier run of `dir` wrote for sensors whose stems are not in `keep`: the names its
// run.json lists, with the extensions a sensor writes and the map files its JSON names. Only plain
// file names inside `dir` are taken from the files (never a path elsewhere).
std::vector<fs::path> staleFiles(const fs::path& dir, const std::set<std::string>& keep) {
  std::vector<fs::path> stale;
  const nlohmann::json report = readJsonOrNull(dir / "run.json");
  if (!report.is_object() || !report.contains("sensors") || !report["sensors"].is_array()) return stale;
  for (const nlohmann::json& s : report["sensors"]) {
    if (!s.is_object() || !s.contains("name") || !s["name"].is_string()) continue;
    const std::string stem = sensorFileStem(s["name"].get<std::string>());
    if (keep.count(stem) != 0) continue;
    const nlohmann::json own = readJsonOrNull(dir / (stem + ".json"));
    if (own.is_object() && own.contains("map_files") && own["map_files"].is_object())
      for (const auto& [key, file] : own["map_files"].items())
        if (file.is_string()) {
          const fs::path name = file.get<std::string>();
          if (name == name.filename() && name != "." && name != "..") stale.push_back(dir / name);
        }
    for (const char* ext : kSensorExtensions) stale.push_back(dir / (stem + ext));
  }
  return stale;
}

}  // namespace

std::string sensorFileStem(const std::string& sensor_name) {
  std::string s = sensor_name;
  for (char& c : s)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '_' || c == '-')) c = '_';
  return s.empty() ? "_" : s;
}

void checkOutputFolder(const fs::path& dir, const std::vector<std::string>& stems, bool resume, bool overwrite) {
  if (resume || overwrite) return;
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return;  // a new folder; a file in the way is refused when it is created
  const std::set<std::string> own(stems.begin(), stems.end());
  std::vector<std::string> found;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    bool ours = name == "run.json" || name == "run_state.bin";
    // A stem may itself hold dots ("lens.front"): any prefix up to a dot can be one.
    for (std::size_t d = name.find('.'); !ours && d != std::string::npos; d = name.find('.', d + 1))
      ours = own.count(name.substr(0, d)) != 0;
    if (ours) found.push_back(name);
  }
  if (ec) throw FileError(dir.string() + ": cannot list the output folder (" + ec.message() + ")");
  if (found.empty()) return;
  // The run's own files first: they say most plainly what the folder holds.
  const auto rank = [](const std::string& f) { return f == "run.json" ? 0 : f == "run_state.bin" ? 1 : 2; };
  std::sort(found.begin(), found.end(),
            [&](const std::string& a, const std::string& b) { return std::pair(rank(a), a) < std::pair(rank(b), b); });
  const bool earlier_run = rank(found.front()) < 2;
  throw InvalidArgument("--out " + dir.string() + " holds " + (earlier_run ? "an earlier run's results" : "files") +
                        " that this run would replace (" + found.front() +
                        (found.size() > 1 ? " and " + std::to_string(found.size() - 1) + " more" : std::string()) +
                        "): --overwrite replaces them, --resume continues the saved run, or choose another --out");
}

SensorOutputSet::SensorOutputSet(fs::path dir) : dir_(std::move(dir)), staging_(dir_ / kStagingName) {
  std::error_code ec;
  fs::create_directories(dir_, ec);
  if (ec) throw FileError(dir_.string() + ": cannot create the output folder (" + ec.message() + ")");
  fs::remove_all(staging_, ec);
  if (ec) throw FileError(staging_.string() + ": cannot remove the stale staging folder (" + ec.message() + ")");
  fs::create_directory(staging_, ec);
  if (ec) throw FileError(staging_.string() + ": cannot create the staging folder (" + ec.message() + ")");
}

SensorOutputSet::~SensorOutputSet() {
  std::error_code ec;
  if (!committed_) fs::remove_all(staging_, ec);
}

void SensorOutputSet::commit(const std::vector<std::string>& stems) {
  std::error_code ec;
  const std::vector<fs::path> stale = staleFiles(dir_, std::set<std::string>(stems.begin(), stems.end()));
  std::vector<fs::path> files;
  for (fs::directory_iterator it(staging_, ec), end; !ec && it != end; it.increment(ec))
    files.push_back(it->path().filename());
  if (ec) throw FileError(staging_.string() + ": cannot list the staging folder (" + ec.message() + ")");
  // run.json last: until it moves, DIR's report is the earlier run's (or none).
  std::stable_partition(files.begin(), files.end(), [](const fs::path& f) { return f != "run.json"; });
  committed_ = true;  // from here on a failure keeps the files not yet moved, as the error says
  for (const fs::path& f : files) {
    fs::rename(staging_ / f, dir_ / f, ec);
    if (ec)
      throw FileError((dir_ / f).string() + ": cannot move the result into the output folder (" + ec.message() +
                      "); the results not yet moved are in " + staging_.string());
  }
  for (const fs::path& f : stale)
    if (std::find(files.begin(), files.end(), f.filename()) == files.end()) fs::remove(f, ec);
  fs::remove(staging_, ec);
}

}  // namespace duplex::cli
