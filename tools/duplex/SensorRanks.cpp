#include "SensorRanks.h"

#include <duplex/accel/Error.h>

#ifdef DUPLEX_HAVE_MPI
#include <duplex/sensors/SensorRunMpi.h>

#include <mpi.h>
#endif

#include <cstdlib>
#include <iostream>

namespace duplex::cli {

namespace {

#ifdef DUPLEX_HAVE_MPI
// Started by an MPI launcher: OpenMPI's mpirun, or a PMI / PMIx one (MPICH's hydra, Slurm's srun).
// A plain start stays a plain process, without MPI's start-up.
bool launchedByMpi() {
  for (const char* v : {"OMPI_COMM_WORLD_SIZE", "PMIX_RANK", "PMI_RANK", "PMI_SIZE"})
    if (std::getenv(v) != nullptr) return true;
  return false;
}
#endif

}  // namespace

SensorRanks::SensorRanks() {
#ifdef DUPLEX_HAVE_MPI
  if (!launchedByMpi()) return;
  int initialised = 0;
  MPI_Initialized(&initialised);
  if (initialised) return;  // an embedding application's MPI: not ours to finalise
  int provided = 0;
  // Only this thread calls MPI; SensorRun's workers never do.
  if (MPI_Init_thread(nullptr, nullptr, MPI_THREAD_FUNNELED, &provided) != MPI_SUCCESS)
    throw Error("cannot initialise MPI (started by mpirun, but MPI_Init_thread failed)");
  shared_ = true;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
  MPI_Comm_size(MPI_COMM_WORLD, &size_);
#endif
}

SensorRanks::~SensorRanks() {
#ifdef DUPLEX_HAVE_MPI
  if (shared_) MPI_Finalize();
#endif
}

void SensorRanks::together(const std::function<void()>& step) {
  if (!shared_) {
    step();
    return;
  }
#ifdef DUPLEX_HAVE_MPI
  std::string problem;
  try {
    step();
  } catch (const std::exception& e) {
    problem = e.what();
    if (problem.empty()) problem = "unknown failure";
  }
  try {
    agreeOnRanks(MPI_COMM_WORLD, problem);
  } catch (const MpiError& e) {
    throw AllRanksFailed(e.what());
  }
#endif
}

SensorRunStatus SensorRanks::runUntil(SensorRun& run, std::uint64_t total_rays,
                                      const std::function<void(const SensorProgress&)>& progress,
                                      const SensorStopRule& stop) {
  if (!shared_) return run.runUntil(total_rays, progress, stop);
#ifdef DUPLEX_HAVE_MPI
  SensorMpiStats stats;
  const SensorRunStatus status = runUntilMpi(run, MPI_COMM_WORLD, total_rays, progress, stop, &stats);
  // The other ranks' work, for rank 0's report.
  const double mine[2] = {static_cast<double>(stats.batches_traced), stats.trace_seconds};
  double all_batches = 0.0, max_trace = 0.0;
  MPI_Reduce(&mine[0], &all_batches, 1, MPI_DOUBLE, MPI_SUM, 0, MPI_COMM_WORLD);
  MPI_Reduce(&mine[1], &max_trace, 1, MPI_DOUBLE, MPI_MAX, 0, MPI_COMM_WORLD);
  if (rank_ == 0) {
    report_ = {{"ranks", size_},
               {"batches", static_cast<std::uint64_t>(all_batches)},
               {"rank0_batches", stats.batches_traced},
               {"tally_bytes_received", stats.tally_bytes_received},
               {"tally_bytes_max", stats.tally_bytes_max},
               {"rank0_trace_seconds", stats.trace_seconds},
               {"rank0_comm_seconds", stats.comm_seconds},
               {"rank0_reduce_seconds", stats.reduce_seconds},
               {"max_trace_seconds", max_trace}};
  }
  return status;
#else
  return run.runUntil(total_rays, progress, stop);
#endif
}

void SensorRanks::barrier() const {
#ifdef DUPLEX_HAVE_MPI
  if (shared_) MPI_Barrier(MPI_COMM_WORLD);
#endif
}

void SensorRanks::failed(const std::exception& e) const {
  if (!shared_) return;
#ifdef DUPLEX_HAVE_MPI
  std::cerr << "duplex sensor: error on rank " << rank_ << " of " << size_ << ": " << e.what()
            << "; ending every rank\n"
            << std::flush;
  MPI_Abort(MPI_COMM_WORLD, 1);
#else
  (void)e;
#endif
}

}  // namespace duplex::cli
