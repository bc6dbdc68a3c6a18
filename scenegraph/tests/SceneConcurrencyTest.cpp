// Queries on several threads while another thread edits and commits the graph: every query sees a
// committed scene, whole (a single query or a whole batch equals the brute force over the visible
// instances of one commit that was current at some moment while it ran). Random edits of every kind
// (add, remove, move, hide, mask, replace the object, deform a library object) between commits. Also
// the test the ThreadSanitizer build runs (DUPLEX_TSAN).

#include "MeshChecks.h"
#include "SceneChecks.h"
#include "TestSupport.h"

#include "duplex/accel/RayGenerator.h"
#include "duplex/scenegraph/SceneGraph.h"
#include "duplex/scenegraph/SceneTracer.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <optional>
#include <random>
#include <thread>
#include <vector>

// ThreadSanitizer (GCC's macro, clang's feature test).
#if defined(__SANITIZE_THREAD__)
#define DUPLEX_TEST_TSAN 1
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
#define DUPLEX_TEST_TSAN 1
#endif
#endif
#ifndef DUPLEX_TEST_TSAN
#define DUPLEX_TEST_TSAN 0
#endif

namespace duplex::test {
namespace {

// A query's results with the commits that bracket it: `first` was the last finished commit when it
// started, `last` the last commit started when it ended.
struct Observed {
  std::uint64_t first = 0, last = 0;
  std::vector<Hit> hits;
  bool batch = false;  // a batch (one state for all rays) or single-ray queries (one state each)
};

bool matches(const std::vector<Hit>& got, const std::vector<Hit>& want, std::size_t ray) {
  return sameHit(got[ray], want[ray]);
}

TEST(SceneConcurrency, QueriesDuringCommitsSeeOneCommittedScene) {
  // Under ThreadSanitizer every thread is one the test starts: oneTBB's own library is not
  // instrumented, so the ordering its workers give (a task's writes before the join) is invisible
  // to the sanitizer and would be reported as races. The query threads and the editing thread then
  // still overlap exactly as in the other builds.
  std::optional<tbb::global_control> one_thread_each;
  if (DUPLEX_TEST_TSAN) one_thread_each.emplace(tbb::global_control::max_allowed_parallelism, 1);
  auto library = std::make_shared<ObjectLibrary>();
  SceneGraph graph(library);
  std::vector<ObjectId> objects;
  objects.push_back(library->add("sphere", buildChecked(icosphere(2))));
  objects.push_back(library->add("box", buildChecked(boxMesh(glm::vec3(-1.0f), glm::vec3(1.0f), "box"))));
  objects.push_back(library->add("grid", buildChecked(flatGrid(6, 2, 0.0f, 0.25f))));
  const std::vector<glm::vec3> rest = dynamic_cast<const MeshObject&>(*library->get(objects[0])).mesh().positions();
  std::mt19937_64 rng(77);
  std::vector<NodeId> parents{kRootNode};
  for (int i = 0; i < 4; ++i) parents.push_back(graph.addTransform(kRootNode, randomPlacement(rng, 6.0)));
  for (int i = 0; i < 40; ++i) {
    // One draw per statement: a call's arguments are evaluated in an order each compiler picks.
    const NodeId parent = parents[rng() % parents.size()];
    const ObjectId object = objects[rng() % objects.size()];
    graph.addInstance(parent, object, randomPlacement(rng, 8.0));
  }
  graph.commit();
  SceneTracer tracer(graph);
  const std::vector<Ray> rays = randomRays(Box(glm::vec3(-9.0f), glm::vec3(9.0f)), 200, 5);
  const auto brute = [&] {
    const Model model = visibleModel(graph);
    std::vector<Hit> hits(rays.size());
    for (std::size_t i = 0; i < rays.size(); ++i) hits[i] = bruteIntersect(model, rays[i], 0xFFFFFFFFu);
    return hits;
  };

  // references[k]: the brute force after commit k (0: the first). Written by the editing thread
  // before it announces the commit as finished, read after the threads are joined.
  constexpr int kCommits = 40;
  std::vector<std::vector<Hit>> references(kCommits + 1);
  references[0] = brute();
  std::atomic<std::uint64_t> finished{0}, started{0};
  std::atomic<bool> stop{false};
  std::mutex results_mutex;
  std::vector<Observed> observed;

  constexpr int kQueryThreads = 2;
  std::vector<std::thread> threads;
  for (int t = 0; t < kQueryThreads; ++t) {
    threads.emplace_back([&, t] {
      tbb::task_arena arena(2);
      QueryContext ctx;
      for (std::uint64_t q = 0; !stop.load(); ++q) {
        Observed o;
        o.first = finished.load();
        o.hits.resize(rays.size());
        o.batch = (q + t) % 2 == 0;
        if (o.batch) arena.execute([&] { tracer.intersect(rays, o.hits); });
        else
          for (std::size_t i = 0; i < rays.size(); ++i) o.hits[i] = tracer.intersect(rays[i], ctx);
        o.last = started.load();
        std::lock_guard lock(results_mutex);
        observed.push_back(std::move(o));
      }
    });
  }

  for (int c = 1; c <= kCommits; ++c) {
    for (int e = 0, n = 1 + static_cast<int>(rng() % 6); e < n; ++e) {
      const std::vector<NodeId> inst = graph.instances();
      const NodeId pick = inst.empty() ? kInvalidNode : inst[rng() % inst.size()];
      switch (inst.size() < 10 ? 0 : rng() % 7) {
        case 0: {
          const NodeId parent = parents[rng() % parents.size()];
          const ObjectId object = objects[rng() % objects.size()];
          graph.addInstance(parent, object, randomPlacement(rng, 8.0));
          break;
        }
        case 1: graph.remove(pick); break;
        case 2: graph.setTransform(pick, randomPlacement(rng, 8.0)); break;
        case 3: graph.setVisible(pick, rng() % 2 == 0); break;
        case 4: graph.setObject(pick, objects[rng() % objects.size()]); break;
        case 5: graph.setTransform(parents[1 + rng() % (parents.size() - 1)], randomPlacement(rng, 6.0)); break;
        default: {
          std::vector<glm::vec3> moved = rest;
          const float s = 0.8f + 0.4f * static_cast<float>(rng() % 100) / 100.0f;
          for (glm::vec3& p : moved) p *= s;
          graph.deformObject(objects[0], moved);
        }
      }
    }
    started.store(c);
    graph.commit();
    references[c] = brute();
    finished.store(c);
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  stop.store(true);
  for (std::thread& t : threads) t.join();

  ASSERT_GT(observed.size(), 20u);
  std::size_t overlapping = 0;
  for (const Observed& o : observed) {
    ASSERT_LE(o.first, o.last);
    overlapping += o.last > o.first;
    if (o.batch) {
      bool one_state = false;
      for (std::uint64_t k = o.first; k <= o.last && !one_state; ++k) {
        one_state = true;
        for (std::size_t i = 0; i < rays.size() && one_state; ++i) one_state = matches(o.hits, references[k], i);
      }
      EXPECT_TRUE(one_state) << "a batch between commits " << o.first << " and " << o.last
                             << " equals no single committed scene";
    } else {
      for (std::size_t i = 0; i < rays.size(); ++i) {
        bool some_state = false;
        for (std::uint64_t k = o.first; k <= o.last && !some_state; ++k) some_state = matches(o.hits, references[k], i);
        EXPECT_TRUE(some_state) << "ray " << i << " between commits " << o.first << " and " << o.last << ": "
                                << o.hits[i];
      }
    }
  }
  // The queries did run across commits (else the test checked nothing concurrent).
  EXPECT_GT(overlapping, 0u);
}

}  // namespace
}  // namespace duplex::test
