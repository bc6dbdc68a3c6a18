// A sensor run shared by the ranks of an MPI communicator: rounds of one batch per rank, the
// tallies sent to rank 0 and added there in batch order (SensorRunMpi.h).
//
// A round: rank 0 broadcasts whether to go on and the round's first batch; every rank traces its
// batch; each other rank sends rank 0 a header (tally bytes, whether the batch is complete,
// whether its run was cancelled) and the tally; rank 0 adds its own, then rank 1's, ... in batch
// order, checking the stop rule after each as runUntil does. Rounds keep every rank in step, so a
// stop (target reached, a signal on any rank) ends all of them after the same batch.

#include "duplex/sensors/SensorRunMpi.h"

#include <algorithm>
#include <array>
#include <bit>
#include <chrono>
#include <climits>
#include <cstring>
#include <sstream>
#include <vector>

namespace duplex {

namespace {

void check(int code, const char* call) {
  if (code == MPI_SUCCESS) return;
  char text[MPI_MAX_ERROR_STRING];
  int length = 0;
  MPI_Error_string(code, text, &length);
  std::ostringstream msg;
  msg << call << " failed: " << std::string(text, static_cast<std::size_t>(length))
      << " (a rank died or lost its connection?)";
  throw MpiError(msg.str());
}

// A duplicate of the caller's communicator that returns errors instead of aborting, so that a
// failed call becomes an MpiError with its message. Freed at the end of a successful run only (a
// free after a failure could wait forever for a lost rank).
class Comm {
 public:
  explicit Comm(MPI_Comm parent) {
    check(MPI_Comm_dup(parent, &comm_), "MPI_Comm_dup");
    check(MPI_Comm_set_errhandler(comm_, MPI_ERRORS_RETURN), "MPI_Comm_set_errhandler");
    check(MPI_Comm_rank(comm_, &rank_), "MPI_Comm_rank");
    check(MPI_Comm_size(comm_, &size_), "MPI_Comm_size");
  }
  void free() { check(MPI_Comm_free(&comm_), "MPI_Comm_free"); }
  Comm(const Comm&) = delete;
  Comm& operator=(const Comm&) = delete;
  [[nodiscard]] MPI_Comm get() const { return comm_; }
  [[nodiscard]] int rank() const { return rank_; }
  [[nodiscard]] int size() const { return size_; }

 private:
  MPI_Comm comm_ = MPI_COMM_NULL;
  int rank_ = 0, size_ = 1;
};

// What a rank tells rank 0 about its batch of a round.
enum TallyState : std::uint64_t { kNoBatch = 0, kComplete = 1, kIncomplete = 2 };
constexpr int kTagHeader = 1, kTagTally = 2;

double since(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

}  // namespace

void agreeOnRanks(MPI_Comm parent, const std::string& problem) {
  Comm comm(parent);
  int mine = problem.empty() ? INT_MAX : comm.rank(), first = INT_MAX;
  check(MPI_Allreduce(&mine, &first, 1, MPI_INT, MPI_MIN, comm.get()), "MPI_Allreduce");
  if (first == INT_MAX) {
    comm.free();
    return;
  }
  // The first failing rank's text, for every rank's message.
  std::uint64_t length = comm.rank() == first ? problem.size() : 0;
  check(MPI_Bcast(&length, 1, MPI_UINT64_T, first, comm.get()), "MPI_Bcast");
  std::string text(std::min<std::uint64_t>(length, 1u << 16), '\0');
  if (comm.rank() == first) text = problem.substr(0, text.size());
  check(MPI_Bcast(text.data(), static_cast<int>(text.size()), MPI_CHAR, first, comm.get()), "MPI_Bcast");
  comm.free();
  std::ostringstream msg;
  msg << "rank " << first << " of " << comm.size() << ": " << text;
  throw MpiError(msg.str());
}

SensorRunStatus runUntilMpi(SensorRun& run, MPI_Comm parent, std::uint64_t total_rays,
                            const std::function<void(const SensorProgress&)>& progress, const SensorStopRule& stop,
                            SensorMpiStats* stats_out) {
  Comm comm(parent);
  const int rank = comm.rank(), ranks = comm.size();
  SensorMpiStats stats;
  stats.rank = rank;
  stats.ranks = ranks;
  const std::uint64_t batch_rays = run.config().batch_rays;

  // Every rank's run must be the same run: scene and configuration (fingerprint), total, stop rule.
  {
    const std::array<std::uint64_t, 6> mine = {run.fingerprint(),
                                               total_rays,
                                               static_cast<std::uint64_t>(static_cast<std::int64_t>(stop.sensor)),
                                               std::bit_cast<std::uint64_t>(stop.target),
                                               stop.min_rays,
                                               batch_rays};
    std::vector<std::uint64_t> all(mine.size() * static_cast<std::size_t>(ranks));
    check(MPI_Allgather(mine.data(), static_cast<int>(mine.size()), MPI_UINT64_T, all.data(),
                        static_cast<int>(mine.size()), MPI_UINT64_T, comm.get()),
          "MPI_Allgather");
    for (int r = 1; r < ranks; ++r) {
      const auto* other = all.data() + mine.size() * static_cast<std::size_t>(r);
      if (!std::equal(all.begin(), all.begin() + static_cast<std::ptrdiff_t>(mine.size()), other)) {
        std::ostringstream msg;
        msg << "rank " << r << " of " << ranks << " runs "
            << (other[0] != all[0] || other[5] != all[5] ? "another scene, seed or configuration"
                : other[1] != all[1]                     ? "another number of rays"
                                                         : "another stop rule")
            << " than rank 0 (every rank must be given the same scene and options)";
        throw MpiError(msg.str());
      }
    }
  }

  if (stop.sensor >= 0) (void)run.relativeStderr(stop.sensor);  // the same rule everywhere: refused on every rank

  const auto t0 = std::chrono::steady_clock::now();
  std::uint64_t start = run.raysDone();
  check(MPI_Bcast(&start, 1, MPI_UINT64_T, 0, comm.get()), "MPI_Bcast");
  const auto targetReached = [&] {
    return stop.sensor >= 0 && run.raysDone() >= stop.min_rays && run.relativeStderr(stop.sensor) <= stop.target;
  };
  const auto report = [&] {
    if (!progress) return;
    SensorProgress p;
    p.rays_done = run.raysDone();
    p.rays_target = total_rays;
    p.rays_this_call = run.raysDone() - start;
    p.seconds = since(t0);
    progress(p);
  };

  // Rank 0's decision before each round: go on (0), or stop with a status.
  std::uint64_t ctl[3] = {0, 0, 0};  // stop, status, next batch
  SensorRunStatus status = SensorRunStatus::Completed;
  bool stopping = false;
  if (rank == 0 && start % batch_rays != 0 && start < total_rays) {
    // A saved state that ends inside a batch: rank 0 finishes it alone, as runUntil would.
    status = run.runUntil(std::min(total_rays, (start / batch_rays + 1) * batch_rays), progress, stop);
    stopping = status != SensorRunStatus::Completed;
  }
  std::vector<std::byte> received;
  double callback_seconds = 0.0;
  for (;;) {
    if (rank == 0) {
      if (!stopping && run.raysDone() >= total_rays) {
        stopping = true;
        status = targetReached() ? SensorRunStatus::TargetReached : SensorRunStatus::Completed;
      } else if (!stopping && targetReached()) {
        stopping = true;
        status = SensorRunStatus::TargetReached;
      }
      ctl[0] = stopping ? 1 : 0;
      ctl[1] = static_cast<std::uint64_t>(status);
      ctl[2] = run.raysDone() / batch_rays;
    }
    auto tc = std::chrono::steady_clock::now();
    check(MPI_Bcast(ctl, 3, MPI_UINT64_T, 0, comm.get()), "MPI_Bcast");
    stats.comm_seconds += since(tc);
    if (ctl[0] != 0) {
      status = static_cast<SensorRunStatus>(ctl[1]);
      break;
    }
    ++stats.rounds;
    const std::uint64_t batches = (total_rays + batch_rays - 1) / batch_rays;
    const std::uint64_t mine = ctl[2] + static_cast<std::uint64_t>(rank);
    SensorBatchTally tally;
    std::uint64_t header[3] = {0, kNoBatch, 0};  // bytes, state, cancelled
    if (mine < batches && !run.cancelled()) {
      const auto tt = std::chrono::steady_clock::now();
      tally = run.traceBatch(mine, total_rays);
      stats.trace_seconds += since(tt);
      ++stats.batches_traced;
      stats.tally_bytes_max = std::max<std::uint64_t>(stats.tally_bytes_max, tally.bytes.size());
      header[0] = tally.bytes.size();
      header[1] = tally.complete ? kComplete : kIncomplete;
    } else if (mine < batches) {
      header[1] = kIncomplete;
    }
    header[2] = run.cancelled() ? 1 : 0;
    if (header[0] > static_cast<std::uint64_t>(INT_MAX))
      throw MpiError("a batch tally of " + std::to_string(header[0]) +
                     " bytes, more than one MPI message holds: use smaller batches");
    tc = std::chrono::steady_clock::now();
    if (rank != 0) {
      check(MPI_Send(header, 3, MPI_UINT64_T, 0, kTagHeader, comm.get()), "MPI_Send");
      if (header[0] != 0)
        check(MPI_Send(tally.bytes.data(), static_cast<int>(header[0]), MPI_BYTE, 0, kTagTally, comm.get()),
              "MPI_Send");
      stats.tally_bytes_sent += header[0];
    } else {
      // Rank 0 adds the round's batches in order; after a stop it still receives the rest.
      for (int r = 0; r < ranks; ++r) {
        std::uint64_t h[3];
        const std::vector<std::byte>* bytes = &tally.bytes;
        if (r == 0) {
          std::copy(header, header + 3, h);
        } else {
          check(MPI_Recv(h, 3, MPI_UINT64_T, r, kTagHeader, comm.get(), MPI_STATUS_IGNORE), "MPI_Recv");
          received.resize(h[0]);
          if (h[0] != 0)
            check(MPI_Recv(received.data(), static_cast<int>(h[0]), MPI_BYTE, r, kTagTally, comm.get(),
                           MPI_STATUS_IGNORE),
                  "MPI_Recv");
          bytes = &received;
          stats.tally_bytes_received += h[0];
        }
        if (h[2] != 0 && !stopping) status = SensorRunStatus::Cancelled;  // stop after this round
        if (stopping || h[1] == kNoBatch) continue;
        if (h[1] == kIncomplete) {
          stopping = true;
          status = SensorRunStatus::Cancelled;
          continue;
        }
        const auto ta = std::chrono::steady_clock::now();
        run.addBatch(*bytes);
        stats.reduce_seconds += since(ta);
        const auto tp = std::chrono::steady_clock::now();
        report();
        callback_seconds += since(tp);
        if (targetReached()) {
          stopping = true;
          status = SensorRunStatus::TargetReached;
        }
      }
      if (status == SensorRunStatus::Cancelled) stopping = true;
    }
    stats.comm_seconds += since(tc);
  }
  // The additions and the progress callbacks (checkpoints) were timed inside the rounds' MPI time.
  stats.comm_seconds -= stats.reduce_seconds + callback_seconds;
  comm.free();
  if (stats_out) *stats_out = stats;
  return status;
}

}  // namespace duplex
