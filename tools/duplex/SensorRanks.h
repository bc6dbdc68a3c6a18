#pragma once
/// \file SensorRanks.h
/// The processes of a `duplex sensor` run: this one alone, or, in a build with MPI
/// (DUPLEX_WITH_MPI) started by an MPI launcher (`mpirun -np N duplex sensor ...`), the ranks of
/// MPI_COMM_WORLD sharing the run's batches (duplex/sensors/SensorRunMpi.h). Rank 0 reads and
/// writes the files; every rank loads the scene and traces.

#include "duplex/accel/Error.h"
#include "duplex/sensors/SensorRun.h"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <exception>
#include <functional>
#include <string>

namespace duplex::cli {

/// A failure that every rank of a shared run saw and reports together (SensorRanks::together).
class AllRanksFailed : public Error {
 public:
  using Error::Error;
};

/// AllRanksFailed after this rank wrote it to stderr (runSensor): the tool exits with its bad-input
/// status without writing it again.
class AllRanksFailedReported : public AllRanksFailed {
 public:
  using AllRanksFailed::AllRanksFailed;
};

/// The processes of one `duplex sensor` run (see the file comment).
class SensorRanks {
 public:
  /// Initialises MPI when this process was started by an MPI launcher in a build with MPI.
  SensorRanks();
  /// Finalises MPI when the constructor initialised it.
  ~SensorRanks();
  SensorRanks(const SensorRanks&) = delete;
  SensorRanks& operator=(const SensorRanks&) = delete;

  /// This process's rank (0 alone).
  [[nodiscard]] int rank() const { return rank_; }
  /// The number of processes (1 alone).
  [[nodiscard]] int size() const { return size_; }
  /// Whether the run is shared through MPI (started by a launcher, even with one rank).
  [[nodiscard]] bool shared() const { return shared_; }

  /// Runs `step` (what may fail on one rank before the run: loading the scene, rank 0's state
  /// file) on every rank. Alone: as is. Shared: a failure on any rank ends every rank together
  /// with AllRanksFailed naming the first failing rank and its message (no rank is left waiting).
  void together(const std::function<void()>& step);
  /// The run to total_rays: SensorRun::runUntil alone, runUntilMpi shared.
  SensorRunStatus runUntil(SensorRun& run, std::uint64_t total_rays,
                           const std::function<void(const SensorProgress&)>& progress, const SensorStopRule& stop);
  /// What a shared run adds to the report (key "mpi": ranks' work and communication); null alone.
  [[nodiscard]] nlohmann::ordered_json report() const { return report_; }
  /// An exception leaving the command on one rank only (not through together()): shared, the
  /// message is printed with the rank and every rank is ended (MPI_Abort), as waiting for this
  /// rank would hang the others; alone, nothing (the caller reports it as usual).
  void failed(const std::exception& e) const;
  /// Waits until every rank of a shared run gets here (nothing when the run is not shared).
  void barrier() const;

 private:
  int rank_ = 0, size_ = 1;
  bool shared_ = false;
  nlohmann::ordered_json report_;
};

}  // namespace duplex::cli
