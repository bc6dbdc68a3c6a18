// A sensor run shared by the ranks of an MPI communicator: rank 0 deals the batches on demand,
// the other ranks trace them and send the tallies back, rank 0 adds every batch in batch order
// (SensorRunMpi.h). Point-to-point messages only, so that no rank waits for a slower one except
// for the batch that is next to be added.

#include "duplex/sensors/SensorRunMpi.h"

#include <algorithm>
#include <array>
#include <bit>
#include <chrono>
#include <climits>
#include <deque>
#include <future>
#include <map>
#include <thread>
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
constexpr int kTagHeader = 1, kTagTally = 2, kTagAssign = 3;

double since(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

// ---- dealing: rank 0 hands out batch numbers, the others trace them and send the tallies back ----
//
// Each other rank keeps kLookahead batches assigned, so that it starts its next batch at once
// while its tally travels; rank 0 traces batches too, between its services, never more than
// 2 N + 2 batches ahead of the next one to add (N ranks; the tallies that arrive out of order
// wait in memory). A faster rank thus asks for more batches: ranks of different speeds share the work as
// they can, and the result does not change, since rank 0 adds the batches in batch order.

constexpr int kLookahead = 2;
constexpr std::uint64_t kStop = ~std::uint64_t{0};  // the assignment that ends a rank's loop

// What a rank sends before a tally: batch, tally bytes, TallyState, cancelled (0 / 1).
using TallyHeader = std::array<std::uint64_t, 4>;

void work(SensorRun& run, const Comm& comm, std::uint64_t total_rays, SensorMpiStats& stats) {
  std::deque<std::uint64_t> queue;  // batches assigned, not yet traced
  std::uint64_t incoming = 0;
  MPI_Request assignment = MPI_REQUEST_NULL;
  check(MPI_Irecv(&incoming, 1, MPI_UINT64_T, 0, kTagAssign, comm.get(), &assignment), "MPI_Irecv");
  bool stopped = false;
  // Tallies on their way: their buffers live until the sends complete.
  struct Outgoing {
    TallyHeader header{};
    std::vector<std::byte> bytes;
    std::array<MPI_Request, 2> requests{MPI_REQUEST_NULL, MPI_REQUEST_NULL};
  };
  std::deque<Outgoing> outgoing;
  const auto send = [&](std::uint64_t batch, std::vector<std::byte> bytes, TallyState state) {
    Outgoing& o = outgoing.emplace_back();
    o.header = {batch, bytes.size(), state, run.cancelled() ? 1u : 0u};
    o.bytes = std::move(bytes);
    if (o.bytes.size() > static_cast<std::size_t>(INT_MAX))
      throw MpiError("a batch tally of " + std::to_string(o.bytes.size()) +
                     " bytes, more than one MPI message holds: use smaller batches");
    check(MPI_Isend(o.header.data(), 4, MPI_UINT64_T, 0, kTagHeader, comm.get(), &o.requests[0]), "MPI_Isend");
    if (!o.bytes.empty())
      check(MPI_Isend(o.bytes.data(), static_cast<int>(o.bytes.size()), MPI_BYTE, 0, kTagTally, comm.get(),
                      &o.requests[1]),
            "MPI_Isend");
    stats.tally_bytes_sent += o.bytes.size();
    // Forget the sends that completed (in order: the oldest first).
    while (!outgoing.empty()) {
      int done = 0;
      check(MPI_Testall(2, outgoing.front().requests.data(), &done, MPI_STATUSES_IGNORE), "MPI_Testall");
      if (!done) break;
      outgoing.pop_front();
    }
  };
  for (;;) {
    // Take the assignments that arrived; wait for one when there is nothing to trace.
    while (!stopped) {
      int arrived = 0;
      const auto tw = std::chrono::steady_clock::now();
      if (queue.empty()) {
        check(MPI_Wait(&assignment, MPI_STATUS_IGNORE), "MPI_Wait");
        arrived = 1;
      } else {
        check(MPI_Test(&assignment, &arrived, MPI_STATUS_IGNORE), "MPI_Test");
      }
      stats.comm_seconds += since(tw);
      if (!arrived) break;
      if (incoming == kStop) {
        stopped = true;
        break;
      }
      queue.push_back(incoming);
      check(MPI_Irecv(&incoming, 1, MPI_UINT64_T, 0, kTagAssign, comm.get(), &assignment), "MPI_Irecv");
    }
    if (stopped) break;
    const std::uint64_t batch = queue.front();
    queue.pop_front();
    if (run.cancelled()) {
      send(batch, {}, kIncomplete);  // a signal here: nothing more is traced
      continue;
    }
    const auto tt = std::chrono::steady_clock::now();
    SensorBatchTally tally = run.traceBatch(batch, total_rays);
    stats.trace_seconds += since(tt);
    ++stats.batches_traced;
    stats.tally_bytes_max = std::max<std::uint64_t>(stats.tally_bytes_max, tally.bytes.size());
    send(batch, std::move(tally.bytes), tally.complete ? kComplete : kIncomplete);
  }
  // Stopped: the batches still assigned are answered untraced, and every send completes.
  for (const std::uint64_t batch : queue) send(batch, {}, kNoBatch);
  const auto tw = std::chrono::steady_clock::now();
  for (Outgoing& o : outgoing) check(MPI_Waitall(2, o.requests.data(), MPI_STATUSES_IGNORE), "MPI_Waitall");
  stats.comm_seconds += since(tw);
}

SensorRunStatus coordinate(SensorRun& run, const Comm& comm, std::uint64_t total_rays,
                           const std::function<void(const SensorProgress&)>& progress, const SensorStopRule& stop,
                           std::uint64_t start, std::chrono::steady_clock::time_point t0, SensorMpiStats& stats) {
  const int ranks = comm.size();
  const std::uint64_t batch_rays = run.config().batch_rays;
  const std::uint64_t batches = (total_rays + batch_rays - 1) / batch_rays;
  const std::uint64_t window = 2 * static_cast<std::uint64_t>(ranks) + 2;
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

  SensorRunStatus status = SensorRunStatus::Completed;
  bool stopping = false;
  if (start % batch_rays != 0 && start < total_rays) {
    // A saved state that ends inside a batch: rank 0 finishes it alone, as runUntil would.
    status = run.runUntil(std::min(total_rays, (start / batch_rays + 1) * batch_rays), progress, stop);
    stopping = status != SensorRunStatus::Completed;
  }
  if (!stopping && run.raysDone() < total_rays && targetReached()) {
    stopping = true;
    status = SensorRunStatus::TargetReached;
  }
  std::uint64_t next = run.raysDone() / batch_rays;  // the next batch to deal
  std::vector<int> outstanding(static_cast<std::size_t>(ranks), 0);
  std::vector<bool> told_to_stop(static_cast<std::size_t>(ranks), false);
  struct Arrived {
    TallyState state;
    std::vector<std::byte> bytes;
  };
  std::map<std::uint64_t, Arrived> arrived;  // by batch, until its turn to be added
  const auto assign = [&](int r) {
    if (stopping || next >= batches) return false;
    check(MPI_Send(&next, 1, MPI_UINT64_T, r, kTagAssign, comm.get()), "MPI_Send");
    ++next;
    ++outstanding[static_cast<std::size_t>(r)];
    return true;
  };
  // One batch to every rank, then a second (a short run still reaches every rank).
  for (int k = 0; k < kLookahead; ++k)
    for (int r = 1; r < ranks; ++r) (void)assign(r);
  // Tallies whose bytes are still arriving: received without waiting, so that rank 0 keeps tracing
  // while a rank that sent a large tally is busy tracing its next batch (and moves the message
  // on only at its next MPI call).
  struct Receiving {
    std::uint64_t batch;
    Arrived tally;
    MPI_Request request = MPI_REQUEST_NULL;
  };
  std::deque<Receiving> receiving;
  // Takes what has arrived: finished tallies, and headers of new ones (each answered at once with
  // the sender's next batch). Returns whether anything happened.
  const auto poll = [&] {
    const auto tw = std::chrono::steady_clock::now();
    bool any = false;
    for (auto it = receiving.begin(); it != receiving.end();) {
      int done = 0;
      check(MPI_Test(&it->request, &done, MPI_STATUS_IGNORE), "MPI_Test");
      if (!done) {
        ++it;
        continue;
      }
      arrived.emplace(it->batch, std::move(it->tally));
      it = receiving.erase(it);
      any = true;
    }
    for (;;) {
      MPI_Status st;
      int flag = 0;
      check(MPI_Iprobe(MPI_ANY_SOURCE, kTagHeader, comm.get(), &flag, &st), "MPI_Iprobe");
      if (!flag) break;
      any = true;
      const int from = st.MPI_SOURCE;
      TallyHeader h{};
      check(MPI_Recv(h.data(), 4, MPI_UINT64_T, from, kTagHeader, comm.get(), MPI_STATUS_IGNORE), "MPI_Recv");
      --outstanding[static_cast<std::size_t>(from)];
      stats.tally_bytes_received += h[1];
      if (h[3] != 0 && !stopping) {  // a signal on that rank: stop after what is finished
        stopping = true;
        status = SensorRunStatus::Cancelled;
      }
      (void)assign(from);
      Receiving r{h[0], Arrived{static_cast<TallyState>(h[2]), std::vector<std::byte>(h[1])}};
      if (r.tally.state == kNoBatch) continue;
      ++stats.batches_received;
      if (h[1] == 0) {
        arrived.emplace(h[0], std::move(r.tally));
        continue;
      }
      check(MPI_Irecv(r.tally.bytes.data(), static_cast<int>(h[1]), MPI_BYTE, from, kTagTally, comm.get(), &r.request),
            "MPI_Irecv");
      receiving.push_back(std::move(r));
    }
    stats.comm_seconds += since(tw);
    return any;
  };
  // Rank 0's own batch is traced on a thread of its own (it never calls MPI), so that this thread
  // answers the other ranks at once instead of after each of its batches: a rank that waited for
  // its next batch until rank 0 finished one would trace no faster than rank 0.
  std::future<SensorBatchTally> tracing;
  const auto collectTrace = [&] {
    if (!tracing.valid() || tracing.wait_for(std::chrono::seconds(0)) != std::future_status::ready) return false;
    SensorBatchTally tally = tracing.get();
    ++stats.batches_traced;
    stats.tally_bytes_max = std::max<std::uint64_t>(stats.tally_bytes_max, tally.bytes.size());
    arrived.emplace(tally.batch, Arrived{tally.complete ? kComplete : kIncomplete, std::move(tally.bytes)});
    return true;
  };
  for (;;) {
    const bool traced = collectTrace();
    // Add, in batch order, what is there.
    for (auto it = arrived.find(run.raysDone() / batch_rays);
         !stopping && run.raysDone() < total_rays && it != arrived.end();
         it = arrived.find(run.raysDone() / batch_rays)) {
      if (it->second.state != kComplete) {
        stopping = true;
        status = SensorRunStatus::Cancelled;
        break;
      }
      const auto ta = std::chrono::steady_clock::now();
      run.addBatch(it->second.bytes);
      stats.reduce_seconds += since(ta);
      arrived.erase(it);
      report();
      if (targetReached()) {
        stopping = true;
        status = SensorRunStatus::TargetReached;
      }
    }
    if (!stopping && run.cancelled()) {
      stopping = true;
      status = SensorRunStatus::Cancelled;
    }
    if (!stopping && run.raysDone() >= total_rays) stopping = true;  // status: Completed
    if (stopping) {
      for (int r = 1; r < ranks; ++r)
        if (!told_to_stop[static_cast<std::size_t>(r)]) {
          check(MPI_Send(&kStop, 1, MPI_UINT64_T, r, kTagAssign, comm.get()), "MPI_Send");
          told_to_stop[static_cast<std::size_t>(r)] = true;
        }
      if (!tracing.valid() && receiving.empty() &&
          std::all_of(outstanding.begin(), outstanding.end(), [](int n) { return n == 0; }))
        break;
    } else if (!tracing.valid() && next < batches && next - run.raysDone() / batch_rays < window) {
      const std::uint64_t batch = next++;
      tracing = std::async(std::launch::async, [&run, &stats, batch, total_rays] {
        const auto tt = std::chrono::steady_clock::now();
        SensorBatchTally tally = run.traceBatch(batch, total_rays);
        stats.trace_seconds += since(tt);  // read by this thread only after get()
        return tally;
      });
    }
    if (!poll() && !traced) std::this_thread::sleep_for(std::chrono::microseconds(100));
  }
  return status;
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
  SensorRunStatus status = SensorRunStatus::Completed;
  if (rank == 0) {
    status = coordinate(run, comm, total_rays, progress, stop, start, t0, stats);
  } else {
    work(run, comm, total_rays, stats);
  }
  // Every rank returns rank 0's status.
  std::uint64_t code = static_cast<std::uint64_t>(status);
  check(MPI_Bcast(&code, 1, MPI_UINT64_T, 0, comm.get()), "MPI_Bcast");
  comm.free();
  if (stats_out) *stats_out = stats;
  return static_cast<SensorRunStatus>(code);
}

}  // namespace duplex
