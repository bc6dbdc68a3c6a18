#pragma once
/// \file SensorOutput.h
/// The output folder of `duplex sensor`: its result files appear as one set or not at all, and an
/// earlier run's results are replaced only when the user says so.

#include <filesystem>
#include <string>
#include <vector>

namespace duplex::cli {

/// The folder's file-name stem of a sensor: characters other than [A-Za-z0-9._-] become '_'.
[[nodiscard]] std::string sensorFileStem(const std::string& sensor_name);

/// Refuses (InvalidArgument naming the folder and the file found) an output folder that holds an
/// earlier run's results: DIR/run.json, DIR/run_state.bin, or a file "<stem>.*" of one of
/// `stems` (the sensors' file stems), unless `resume` (the run continues the saved one and
/// replaces its results) or `overwrite`. Files of other names (the scene, notes) are no reason.
void checkOutputFolder(const std::filesystem::path& dir, const std::vector<std::string>& stems, bool resume,
                       bool overwrite);

/// The result files of one run, written into a staging folder inside the output folder
/// (DIR/.duplex-sensor-staging) and moved into DIR by commit() once every one of them is complete:
/// a failure while writing (a full disk, a signal) leaves DIR as it was. commit() moves run.json
/// last, so a complete new report only ever sits beside its own files, and removes the files that
/// an earlier run's report (the DIR/run.json it replaces) lists for sensors this run no longer has.
/// Destroyed without commit(), the staging folder and what it holds are removed.
class SensorOutputSet {
 public:
  /// Creates DIR (if needed) and an empty staging folder in it (removing a stale one left by a
  /// process killed while writing). Throws FileError naming the folder when it cannot.
  explicit SensorOutputSet(std::filesystem::path dir);
  SensorOutputSet(const SensorOutputSet&) = delete;
  SensorOutputSet& operator=(const SensorOutputSet&) = delete;
  /// Removes the staging folder unless commit() succeeded.
  ~SensorOutputSet();

  /// The folder to write the result files into (the staging folder).
  [[nodiscard]] const std::filesystem::path& staging() const { return staging_; }

  /// Moves every file of the staging folder into DIR (replacing files of the same name),
  /// run.json last, then removes the earlier run's files of sensors not in `stems` and the
  /// staging folder. Throws FileError naming the file that could not be moved.
  void commit(const std::vector<std::string>& stems);

 private:
  std::filesystem::path dir_, staging_;
  bool committed_ = false;
};

}  // namespace duplex::cli
