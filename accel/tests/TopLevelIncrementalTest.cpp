// The incremental top level: thousands of random edits (insert, remove, move, replace the object,
// change the mask) committed in random batches; after each commit the tree's invariants hold and
// closest hits, occlusion and intersectAll agree exactly with a brute force over the live instances
// (each instance's own bottom-level query on the same object-space ray) and with a fresh build.

#include "MeshChecks.h"
#include "TestSupport.h"
#include "TwoLevelChecks.h"

#include "duplex/accel/Affine.h"
#include "duplex/accel/Error.h"
#include "duplex/accel/KdTraversal.h"
#include "duplex/accel/QueryContext.h"
#include "duplex/accel/RayGenerator.h"
#include "duplex/accel/TopLevel.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/accel/KdTree.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <random>
#include <set>
#include <string>
#include <type_traits>
#include <vector>

namespace duplex::test {
namespace {

struct Objects {
  std::vector<std::shared_ptr<const MeshObject>> list;
  Objects() {
    list.push_back(buildChecked(icosphere(2)));
    list.push_back(buildChecked(boxMesh(glm::vec3(-1.0f), glm::vec3(1.0f), "unit-box")));
    list.push_back(buildChecked(flatGrid(6, 2, 0.0f, 0.25f)));
    list.push_back(buildChecked(triangleSoup(120, 7)));
  }
};

const Objects& objects() {
  static const Objects o;
  return o;
}

struct EditRun {
  std::size_t edits = 0, commits = 0, rays_checked = 0, hits = 0;
};

EditRun runRandomEdits(TopLevelUpdate mode, std::size_t total_edits, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  const auto& objs = objects().list;
  const double spread = 14.0;
  Model model;
  TopLevelConfig config;
  config.update = mode;
  // Small scenes and large batches would otherwise be rebuilt in full: test the incremental path.
  config.min_incremental_instances = 0;
  config.max_incremental_fraction = 1.0;
  TopLevel top(config);
  std::uint32_t next_id = 1;
  std::vector<InstanceDesc> initial;
  for (int i = 0; i < 40; ++i) {
    InstanceDesc d{objs[rng() % objs.size()], randomPlacement(rng, spread), next_id++, 0xFFFFFFFFu};
    model[d.id] = d;
    initial.push_back(d);
  }
  top.build(initial);
  EditRun run;
  const Box world(glm::vec3(-0.6f * float(spread)), glm::vec3(0.6f * float(spread)));
  while (run.edits < total_edits) {
    const int batch = 1 + static_cast<int>(rng() % 12);
    for (int e = 0; e < batch; ++e, ++run.edits) {
      const int kind = static_cast<int>(rng() % 10);
      auto pick = [&]() {
        auto it = model.begin();
        std::advance(it, static_cast<long>(rng() % model.size()));
        return it->first;
      };
      if (kind < 2 || model.size() < 10) {  // insert
        InstanceDesc d{objs[rng() % objs.size()], randomPlacement(rng, spread), next_id++,
                       rng() % 4 == 0 ? 2u : 0xFFFFFFFFu};
        top.set(d);
        model[d.id] = d;
      } else if (kind < 4) {  // remove
        const std::uint32_t id = pick();
        top.remove(id);
        model.erase(id);
      } else if (kind < 8) {  // move a little (the common CAD edit) or far
        const std::uint32_t id = pick();
        InstanceDesc d = model[id];
        std::uniform_real_distribution<double> u(-1.0, 1.0);
        const double step = rng() % 4 == 0 ? spread : 0.05 * spread;
        d.world_from_object.translation += step * draw3<glm::dvec3>(u, rng);
        top.set(d);
        model[id] = d;
      } else if (kind < 9) {  // replace the object
        const std::uint32_t id = pick();
        InstanceDesc d = model[id];
        d.object = objs[rng() % objs.size()];
        top.set(d);
        model[id] = d;
      } else {  // change the mask
        const std::uint32_t id = pick();
        InstanceDesc d = model[id];
        d.mask = d.mask == 2u ? 0xFFFFFFFFu : 2u;
        top.set(d);
        model[id] = d;
      }
    }
    top.commit();
    ++run.commits;
    EXPECT_EQ(top.size(), model.size());
    const auto tree_ok = checkIncrementalTree(top, model);
    EXPECT_TRUE(tree_ok) << "after commit " << run.commits;
    if (!tree_ok) break;

    // Rays: random through the world box, some with a mask that selects only mask-2 instances.
    std::vector<InstanceDesc> live;
    for (const auto& [id, d] : model) live.push_back(d);
    TopLevel fresh;
    fresh.build(live);
    // A top level of at most 256 instances keeps its root tight after every commit (a loose root
    // makes rays that miss everything walk the margin); a fresh build's root is the boxes' union.
    if (live.size() <= 256 && !(top.tree().bounds == fresh.tree().bounds)) {
      ADD_FAILURE() << "commit " << run.commits << ": root " << top.tree().bounds << " is not the tight "
                    << fresh.tree().bounds;
      break;
    }
    const std::vector<Ray> rays = randomRays(world, 60, seed * 1000 + run.commits);
    QueryContext ctx;
    std::size_t failures = 0;
    for (std::size_t r = 0; r < rays.size(); ++r) {
      const std::uint32_t mask = r % 3 == 0 ? 2u : 0xFFFFFFFFu;
      const Hit got = top.intersect(rays[r], ctx, mask);
      const Hit want = bruteIntersect(model, rays[r], mask);
      const Hit rebuilt = fresh.intersect(rays[r], ctx, mask);
      ++run.rays_checked;
      run.hits += got.valid();
      const auto a = sameHit(got, want), b = sameHit(got, rebuilt);
      const bool occ = top.occluded(rays[r], ctx, mask);
      if ((!a || !b || occ != want.valid()) && failures++ < 4)
        ADD_FAILURE() << "commit " << run.commits << ", ray " << r << " " << rays[r] << " mask " << mask
                      << ": incremental vs brute force: " << a.message() << "; vs fresh build: " << b.message()
                      << "; occluded " << occ;
    }
    if (failures) break;
  }
  return run;
}

TEST(TopLevelIncremental, RandomEditsAgreeWithBruteForceAndFreshBuild) {
  const EditRun run = runRandomEdits(TopLevelUpdate::Incremental, 4000, 11);
  EXPECT_GE(run.commits, 500u);
  EXPECT_GT(run.hits, run.rays_checked / 20);
}

TEST(TopLevelIncremental, FullRebuildModeAgreesToo) {
  const EditRun run = runRandomEdits(TopLevelUpdate::FullRebuild, 600, 12);
  EXPECT_GT(run.hits, run.rays_checked / 10);
}

TEST(TopLevelIncremental, IntersectAllListsEveryInstanceHitSorted) {
  const auto& objs = objects().list;
  // A row of unit boxes along x; a ray down the row crosses each box twice.
  std::vector<InstanceDesc> row;
  for (std::uint32_t i = 0; i < 5; ++i)
    row.push_back(
        {objs[1], Affine::fromRowMajor3x4({1, 0, 0, 4.0 * i, 0, 1, 0, 0, 0, 0, 1, 0}), 10 + i, i % 2 ? 1u : 2u});
  TopLevel top;
  top.build(row);
  Ray r;
  r.origin = glm::vec3(-5.0f, 0.1f, 0.2f);
  r.dir = glm::vec3(1.0f, 0.0f, 0.0f);
  QueryContext ctx;
  std::vector<Hit> hits;
  top.intersectAll(r, hits, ctx);
  ASSERT_EQ(hits.size(), 10u);
  for (std::size_t k = 0; k < hits.size(); ++k) {
    EXPECT_EQ(hits[k].instance_id, 10 + k / 2);
    const float expected = 4.0f * float(k / 2) + (k % 2 ? 6.0f : 4.0f);
    EXPECT_NEAR(hits[k].t, expected, 1e-5f);
  }
  top.intersectAll(r, hits, ctx, 1u);  // only the odd boxes
  ASSERT_EQ(hits.size(), 4u);
  EXPECT_EQ(hits[0].instance_id, 11u);
  EXPECT_EQ(hits[3].instance_id, 13u);
}

TEST(TopLevelIncremental, RegionQueryMatchesBoxTest) {
  const auto& objs = objects().list;
  std::mt19937_64 rng(5);
  std::vector<InstanceDesc> all;
  for (std::uint32_t i = 0; i < 300; ++i) all.push_back({objs[i % objs.size()], randomPlacement(rng, 40.0), i + 1});
  TopLevel top;
  top.build(all);
  // Move a third incrementally so the query also runs on an updated tree.
  for (std::uint32_t i = 0; i < 100; ++i) {
    all[i].world_from_object.translation += glm::dvec3(3.0, -2.0, 1.0);
    top.set(all[i]);
  }
  top.commit();
  std::uniform_real_distribution<double> u(-20.0, 20.0);
  for (int q = 0; q < 50; ++q) {
    // An axis-aligned query box as six planes n.x <= d.
    const glm::dvec3 a = draw3<glm::dvec3>(u, rng), b = draw3<glm::dvec3>(u, rng);
    const glm::dvec3 lo = glm::min(a, b), hi = glm::max(a, b);
    const std::vector<glm::dvec4> planes = {{1, 0, 0, hi.x},   {-1, 0, 0, -lo.x}, {0, 1, 0, hi.y},
                                            {0, -1, 0, -lo.y}, {0, 0, 1, hi.z},   {0, 0, -1, -lo.z}};
    std::vector<std::uint32_t> want;
    for (const InstanceDesc& d : all) {
      const Box bb = top.instanceBounds(d.id);
      if (bb.lo.x <= hi.x && bb.hi.x >= lo.x && bb.lo.y <= hi.y && bb.hi.y >= lo.y && bb.lo.z <= hi.z &&
          bb.hi.z >= lo.z)
        want.push_back(d.id);
    }
    std::sort(want.begin(), want.end());
    EXPECT_EQ(top.instancesInRegion(planes), want) << "query " << q;
  }
}

TEST(TopLevelIncremental, SingleMoveTouchesOnlyTheTopLevelLocally) {
  const auto& objs = objects().list;
  std::mt19937_64 rng(9);
  std::vector<InstanceDesc> all;
  for (std::uint32_t i = 0; i < 2000; ++i) all.push_back({objs[i % objs.size()], randomPlacement(rng, 200.0), i});
  TopLevel top;
  top.build(all);
  const auto before = top.stats();
  for (int k = 0; k < 200; ++k) {
    InstanceDesc d = all[rng() % all.size()];
    d.world_from_object.translation += glm::dvec3(1.0, 0.5, -0.5);
    all[d.id] = d;
    top.set(d);
    top.commit();
  }
  const auto after = top.stats();
  EXPECT_EQ(after.commits - before.commits, 200u);
  // Small moves in a big scene: the quality stays within the rebuild ratio without full rebuilds.
  EXPECT_LE(after.full_rebuilds - before.full_rebuilds, 2u);
  EXPECT_LE(after.sah_cost, top.config().rebuild_ratio * after.fresh_sah_cost * 1.0000001);
  EXPECT_TRUE(checkIncrementalTree(top, [&] {
    Model m;
    for (const auto& d : all) m[d.id] = d;
    return m;
  }()));
}

// Many single moves and add / remove pairs with full rebuilds switched off: the local rebuilds
// (leaves, jump subtrees, frontier subtrees) alone must keep the SAH cost within 5% of a fresh
// build over the same boxes, so that tracing stays as fast as over a fresh tree. Without the
// frontier rebuilds this scene drifts well beyond that.
TEST(TopLevelIncremental, ManySmallEditsKeepTheCostNearAFreshBuild) {
  const auto& objs = objects().list;
  std::mt19937_64 rng(17);
  std::vector<InstanceDesc> all;
  for (std::uint32_t i = 0; i < 4000; ++i) all.push_back({objs[i % objs.size()], randomPlacement(rng, 120.0), i});
  TopLevelConfig config;
  config.rebuild_ratio = 1e9;  // local rebuilds only
  TopLevel top(config);
  top.build(all);
  std::uniform_real_distribution<double> step(-4.0, 4.0);
  std::uint32_t next_id = 100000;
  for (int k = 0; k < 2500; ++k) {
    InstanceDesc& d = all[rng() % all.size()];
    d.world_from_object.translation += randomStep(rng, step);
    top.set(d);
    top.commit();
    if (k % 2 == 0) {
      // An instance added next to another one and removed again: nothing may stay behind.
      InstanceDesc extra = all[rng() % all.size()];
      extra.id = next_id++;
      extra.world_from_object.translation += randomStep(rng, step);
      top.set(extra);
      top.commit();
      top.remove(extra.id);
      top.commit();
    }
  }
  const TopLevelStats after = top.stats();
  EXPECT_EQ(after.full_rebuilds, 1u);
  EXPECT_GT(after.subtree_rebuilds, 0u);
  TopLevel fresh;
  fresh.build(all);
  const double fresh_cost = fresh.stats().tree.sah_cost;
  EXPECT_LE(after.tree.sah_cost, 1.05 * fresh_cost) << "fresh " << fresh_cost;
  // The tracked cost is exact after local rebuilds (they are rooted at their cells).
  EXPECT_NEAR(after.sah_cost, after.tree.sah_cost, 1e-6 * after.tree.sah_cost);
  EXPECT_TRUE(checkIncrementalTree(top, [&] {
    Model m;
    for (const auto& d : all) m[d.id] = d;
    return m;
  }()));
}

TEST(TopLevelIncremental, BadConfigurationIsRefusedAndChangesNothing) {
  static_assert(!std::is_copy_constructible_v<TopLevel>, "a copy would share the instance records");
  const auto& objs = objects().list;
  std::mt19937_64 rng(21);
  std::vector<InstanceDesc> all;
  for (std::uint32_t i = 0; i < 300; ++i) all.push_back({objs[i % objs.size()], randomPlacement(rng, 30.0), i});
  TopLevel top;
  top.build(all);
  const std::vector<Ray> rays = randomRays(top.bounds(), 300, 4);
  QueryContext ctx;
  std::vector<Hit> before;
  for (const Ray& r : rays) before.push_back(top.intersect(r, ctx));
  KdBuildConfig bad;
  bad.max_depth = -1;
  expectErrorNaming<InvalidArgument>([&] { top.build(std::span(all).first(1), bad); }, "max_depth");
  TopLevelConfig worse;
  worse.build.intersection_cost = 0.0f;
  expectErrorNaming<InvalidArgument>([&] { top.setConfig(worse); }, "intersection_cost");
  expectErrorNaming<InvalidArgument>([&] { TopLevel t(worse); }, "intersection_cost");
  EXPECT_EQ(top.size(), all.size());
  for (std::size_t i = 0; i < rays.size(); ++i) ASSERT_TRUE(sameHit(top.intersect(rays[i], ctx), before[i])) << i;
}

TEST(TopLevelIncremental, RejectedEditsChangeNothing) {
  const auto& objs = objects().list;
  TopLevel top;
  std::vector<InstanceDesc> two = {{objs[0], Affine::identity(), 1}, {objs[1], Affine::identity(), 2}};
  top.build(two);
  Affine nan = Affine::identity();
  nan.translation.x = std::numeric_limits<double>::quiet_NaN();
  Affine singular = Affine::identity();
  singular.linear[2] = glm::dvec3(0.0);
  expectErrorNaming<InvalidArgument>([&] { top.set({objs[0], nan, 3}); }, "instance 3");
  expectErrorNaming<InvalidArgument>([&] { top.set({objs[0], singular, 4}); }, "singular");
  expectErrorNaming<InvalidArgument>([&] { top.set({nullptr, Affine::identity(), 5}); }, "instance 5");
  expectErrorNaming<InvalidArgument>([&] { top.remove(77); }, "77");
  expectErrorNaming<InvalidArgument>(
      [&] {
        top.build(std::vector<InstanceDesc>{{objs[0], Affine::identity(), 9}, {objs[1], nan, 9}});
      },
      "instance 9");
  top.commit();
  EXPECT_EQ(top.size(), 2u);
  EXPECT_TRUE(top.contains(1));
  EXPECT_FALSE(top.contains(3));
  EXPECT_FALSE(top.contains(9));
  // Remove then re-add in one batch; add then remove in one batch.
  top.remove(1);
  EXPECT_FALSE(top.contains(1));
  top.set({objs[2], Affine::identity(), 1});
  top.set({objs[2], Affine::identity(), 6});
  top.remove(6);
  top.commit();
  EXPECT_EQ(top.size(), 2u);
  EXPECT_FALSE(top.contains(6));
}

}  // namespace
}  // namespace duplex::test
