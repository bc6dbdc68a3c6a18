#pragma once
/// \file SensorRunMpi.h
/// A sensor run shared by the processes (ranks) of an MPI communicator, with the results of a
/// one-process run: duplex::sensors_mpi, built when DUPLEX_WITH_MPI is ON.
///
/// Every rank holds a SensorRun over the same scene and configuration (checked: the runs'
/// fingerprints, the total and the stop rule must agree). Batches (SensorRunConfig::batch_rays,
/// which does not depend on the number of ranks) are dealt by rank 0 on demand: every other rank
/// keeps two batches assigned, traces them with its own threads (SensorRun::traceBatch) and sends
/// each tally to rank 0, which is given its next batch at once; rank 0 traces batches too, and adds
/// all of them in batch order (SensorRun::addBatch). Faster ranks trace more batches. Rank 0's run
/// therefore ends with the
/// accumulators, results and run state of a one-process run of the same seed and total, bit for
/// bit, for any number of ranks and threads per rank; the other ranks' runs only trace.
///
/// Threading: call from the thread that initialised MPI (MPI_THREAD_FUNNELED is enough: the
/// workers of SensorRun never call MPI). Failures: an MPI error on any call, or a rank whose run
/// differs, ends the call with MpiError on the ranks that see it; MPI itself ends the job when a
/// rank dies (OpenMPI's mpirun kills the others), so rank 0's last saved state stays as it was.

#include "duplex/accel/Error.h"
#include "duplex/sensors/SensorRun.h"

#include <mpi.h>

#include <cstdint>
#include <functional>
#include <string>

namespace duplex {

/// A failed MPI call or a disagreement between ranks (another scene, a rank that could not load).
class MpiError : public Error {
 public:
  using Error::Error;
};

/// What one rank did in runUntilMpi (for benchmarks and reports).
struct SensorMpiStats {
  int rank = 0;                            ///< this process's rank in the communicator
  int ranks = 1;                           ///< ranks in the communicator
  std::uint64_t batches_traced = 0;        ///< batches this rank traced
  std::uint64_t batches_received = 0;      ///< rank 0: tallies of batches the other ranks traced
  std::uint64_t tally_bytes_sent = 0;      ///< bytes of batch tallies this rank sent (0 on rank 0)
  std::uint64_t tally_bytes_received = 0;  ///< bytes of batch tallies rank 0 received (0 elsewhere)
  std::uint64_t tally_bytes_max = 0;       ///< the largest batch tally this rank made, bytes
  double trace_seconds = 0.0;              ///< wall time in traceBatch
  /// Wall time in MPI calls (sends, receives, and waiting for batches or tallies of other ranks).
  double comm_seconds = 0.0;
  double reduce_seconds = 0.0;  ///< rank 0: wall time adding the batches (SensorRun::addBatch)
};

/// Collective over `comm`: every rank passes what went wrong on it before the run (empty: nothing,
/// e.g. its scene loaded). Returns when every rank passed an empty text; otherwise throws MpiError
/// on every rank, naming the first failing rank and its text ("rank 2 of 3: ..."), so that all end
/// together instead of waiting for a rank that will never join the run.
void agreeOnRanks(MPI_Comm comm, const std::string& problem);

/// Collective over `comm`: runs `run` to total_rays shared by every rank (see the file comment),
/// like SensorRun::runUntil. Rank 0's run holds the accumulators: the run starts from its
/// raysDone() (a loaded state may end inside a batch: rank 0 finishes that batch alone first), and
/// ends with them; the other ranks' runs are left as they were. `progress` is called on rank 0
/// after each batch it adds (its checkpoints see whole batches), `stop` is checked on rank 0 after
/// each batch, as runUntil does, so every rank count stops at the same batch (batches traced past
/// it are dropped). A cancel() of any rank's run (a signal handler) stops every rank: rank 0 keeps
/// the finished batches that follow the run's end without a gap. Returns the same status on every
/// rank. Throws MpiError (ranks whose
/// runs, totals or stop rules differ, a failed MPI call) and what runUntil throws (no light).
SensorRunStatus runUntilMpi(SensorRun& run, MPI_Comm comm, std::uint64_t total_rays,
                            const std::function<void(const SensorProgress&)>& progress = {},
                            const SensorStopRule& stop = {}, SensorMpiStats* stats = nullptr);

}  // namespace duplex
