/// \file ObjectLibraryTest.cpp
/// ObjectLibrary: names, errors, deferred builds (once under concurrent get(), failures rethrown
/// naming the object and retried), parallel buildAll.

#include "duplex/accel/Error.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/scenegraph/ObjectLibrary.h"

#include "MeshChecks.h"
#include "TestSupport.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <latch>
#include <stdexcept>
#include <thread>
#include <vector>

namespace duplex {
namespace {

using test::expectErrorNaming;
using test::tinyMeshObject;
using namespace std::chrono_literals;

TEST(ObjectLibrary, AddFindAndNames) {
  ObjectLibrary lib;
  const ObjectId a = lib.add("a", tinyMeshObject("a"));
  const ObjectId b = lib.addDeferred("b", "mesh", [] { return tinyMeshObject("b"); });
  EXPECT_EQ(a, 0u);
  EXPECT_EQ(b, 1u);
  EXPECT_EQ(lib.size(), 2u);
  EXPECT_EQ(lib.find("a"), a);
  EXPECT_EQ(lib.find("b"), b);
  EXPECT_EQ(lib.find("c"), std::nullopt);
  EXPECT_EQ(lib.name(b), "b");
  EXPECT_EQ(lib.typeName(a), "mesh");
  EXPECT_TRUE(lib.isBuilt(a));
  EXPECT_FALSE(lib.isBuilt(b));
  EXPECT_EQ(lib.buildCount(), 0u);  // add() of a built object is not a factory call
  expectErrorNaming<InvalidArgument>([&] { (void)lib.name(7); }, "7");
  expectErrorNaming<InvalidArgument>([&] { (void)lib.get(kInvalidObject); }, std::to_string(kInvalidObject));
}

TEST(ObjectLibrary, BadAddsAreRejectedAndChangeNothing) {
  ObjectLibrary lib;
  (void)lib.add("a", tinyMeshObject("a"));
  expectErrorNaming<InvalidArgument>([&] { (void)lib.add("a", tinyMeshObject("a")); }, "'a'");
  expectErrorNaming<InvalidArgument>([&] { (void)lib.addDeferred("a", "mesh", [] { return tinyMeshObject("a"); }); },
                                     "'a'");
  EXPECT_THROW((void)lib.add("", tinyMeshObject("x")), InvalidArgument);
  EXPECT_THROW((void)lib.add("n", nullptr), InvalidArgument);
  EXPECT_THROW((void)lib.addDeferred("f", "mesh", nullptr), InvalidArgument);
  EXPECT_EQ(lib.size(), 1u);
  EXPECT_EQ(lib.find("n"), std::nullopt);
  EXPECT_EQ(lib.find("f"), std::nullopt);
  // The rejected names are still free.
  EXPECT_EQ(lib.add("n", tinyMeshObject("n")), 1u);
}

TEST(ObjectLibrary, DeferredObjectIsBuiltOnceUnderConcurrentGet) {
  ObjectLibrary lib;
  std::atomic<int> calls{0};
  const ObjectId id = lib.addDeferred("slow", "mesh", [&calls] {
    calls.fetch_add(1);
    std::this_thread::sleep_for(30ms);  // long enough for every thread to arrive during the build
    return tinyMeshObject("slow");
  });
  constexpr int kThreads = 12;
  std::latch start(kThreads);
  std::vector<std::shared_ptr<const Object>> got(kThreads);
  std::vector<std::thread> threads;
  for (int i = 0; i < kThreads; ++i)
    threads.emplace_back([&, i] {
      start.arrive_and_wait();
      got[i] = lib.get(id);
    });
  for (auto& t : threads) t.join();
  EXPECT_EQ(calls.load(), 1);
  EXPECT_EQ(lib.buildCount(), 1u);
  EXPECT_TRUE(lib.isBuilt(id));
  for (const auto& g : got) {
    ASSERT_NE(g, nullptr);
    EXPECT_EQ(g.get(), got[0].get());
  }
  EXPECT_EQ(lib.get(id).get(), got[0].get());
  EXPECT_EQ(calls.load(), 1);
}

TEST(ObjectLibrary, FailedBuildIsRethrownNamingTheObjectAndRetried) {
  ObjectLibrary lib;
  std::atomic<int> calls{0};
  const ObjectId id = lib.addDeferred("flaky", "mesh", [&calls]() -> std::shared_ptr<const Object> {
    if (calls.fetch_add(1) == 0) throw std::runtime_error("disk on fire");
    return tinyMeshObject("flaky");
  });
  expectErrorNaming<InvalidArgument>([&] { (void)lib.get(id); }, "flaky");
  expectErrorNaming<InvalidArgument>([&] { (void)lib.get(kInvalidObject); }, "unknown");
  EXPECT_EQ(calls.load(), 1);
  EXPECT_FALSE(lib.isBuilt(id));
  EXPECT_EQ(lib.buildCount(), 0u);
  const auto obj = lib.get(id);  // tried again
  ASSERT_NE(obj, nullptr);
  EXPECT_EQ(calls.load(), 2);
  EXPECT_TRUE(lib.isBuilt(id));
  EXPECT_EQ(lib.buildCount(), 1u);

  // The cause is in the message too, and a null result is a failure.
  const ObjectId bad = lib.addDeferred(
      "broken", "mesh", []() -> std::shared_ptr<const Object> { throw std::runtime_error("disk on fire"); });
  expectErrorNaming<InvalidArgument>([&] { (void)lib.get(bad); }, "disk on fire");
  const ObjectId null = lib.addDeferred("nothing", "mesh", [] { return std::shared_ptr<const Object>(); });
  expectErrorNaming<InvalidArgument>([&] { (void)lib.get(null); }, "nothing");
  EXPECT_FALSE(lib.isBuilt(null));
}

TEST(ObjectLibrary, BuildAllRunsFactoriesInParallel) {
  if (std::thread::hardware_concurrency() < 2) GTEST_SKIP() << "needs two hardware threads";
  ObjectLibrary lib;
  std::atomic<int> in_flight{0};
  std::atomic<int> max_in_flight{0};
  std::atomic<int> calls{0};
  std::vector<ObjectId> ids;
  for (int i = 0; i < 8; ++i) {
    std::string name = "o";
    name += std::to_string(i);  // not "o" + ...: GCC 12 -Wrestrict false positive
    ids.push_back(lib.addDeferred(name, "mesh", [&, name] {
      calls.fetch_add(1);
      const int now = in_flight.fetch_add(1) + 1;
      for (int seen = max_in_flight.load(); now > seen && !max_in_flight.compare_exchange_weak(seen, now);) {
      }
      // Wait (bounded) until another factory runs at the same time: a serial buildAll never gets there.
      const auto deadline = std::chrono::steady_clock::now() + 3s;
      while (max_in_flight.load() < 2 && std::chrono::steady_clock::now() < deadline) std::this_thread::sleep_for(1ms);
      in_flight.fetch_sub(1);
      return tinyMeshObject(name);
    }));
  }
  lib.buildAll();
  EXPECT_GE(max_in_flight.load(), 2);
  EXPECT_EQ(calls.load(), 8);
  EXPECT_EQ(lib.buildCount(), 8u);
  for (const ObjectId id : ids) EXPECT_TRUE(lib.isBuilt(id));
  lib.buildAll();  // nothing left to build
  EXPECT_EQ(calls.load(), 8);
}

TEST(ObjectLibrary, BuildAllReportsTheFirstFailureAfterBuildingTheRest) {
  ObjectLibrary lib;
  const auto failing = [](const char* why) {
    return [why]() -> std::shared_ptr<const Object> { throw std::runtime_error(why); };
  };
  const ObjectId ok1 = lib.addDeferred("ok1", "mesh", [] { return tinyMeshObject("ok1"); });
  const ObjectId bad1 = lib.addDeferred("bad1", "mesh", failing("first reason"));
  const ObjectId ok2 = lib.addDeferred("ok2", "mesh", [] { return tinyMeshObject("ok2"); });
  const ObjectId bad2 = lib.addDeferred("bad2", "mesh", failing("second reason"));
  const std::vector<ObjectId> ids{ok1, bad1, ok2, bad2};
  expectErrorNaming<InvalidArgument>([&] { lib.buildAll(ids); }, "bad1");
  EXPECT_TRUE(lib.isBuilt(ok1));
  EXPECT_TRUE(lib.isBuilt(ok2));
  EXPECT_FALSE(lib.isBuilt(bad1));
  EXPECT_FALSE(lib.isBuilt(bad2));
  EXPECT_EQ(lib.buildCount(), 2u);
  // Only bad2 is listed: its own failure is reported.
  const std::vector<ObjectId> only_bad2{bad2};
  expectErrorNaming<InvalidArgument>([&] { lib.buildAll(only_bad2); }, "second reason");

  // An unknown id is refused before anything is built.
  const ObjectId later = lib.addDeferred("later", "mesh", [] { return tinyMeshObject("later"); });
  const std::vector<ObjectId> with_unknown{later, 99};
  EXPECT_THROW(lib.buildAll(with_unknown), InvalidArgument);
  EXPECT_FALSE(lib.isBuilt(later));
}

TEST(ObjectLibrary, ACancelledBuildAllKeepsNothingAndProgressCountsEveryObject) {
  ObjectLibrary lib;
  std::vector<ObjectId> ids;
  for (int i = 0; i < 12; ++i) {
    std::string name = std::to_string(i);
    name.insert(0, "o");
    ids.push_back(lib.addDeferred(name, "mesh", [name] { return tinyMeshObject(name); }));
  }
  CancelToken token;
  std::vector<std::pair<std::size_t, std::size_t>> reports;
  WorkControl control;
  control.cancel = &token;
  control.progress = [&](std::size_t done, std::size_t total) {
    reports.emplace_back(done, total);
    if (done == 3) token.cancel();
  };
  EXPECT_THROW(lib.buildAll(control), Cancelled);
  for (const ObjectId id : ids) EXPECT_FALSE(lib.isBuilt(id)) << lib.name(id);
  EXPECT_EQ(lib.buildCount(), 0u);
  ASSERT_GE(reports.size(), 3u);
  for (std::size_t i = 0; i < reports.size(); ++i) {
    EXPECT_EQ(reports[i].first, i + 1);
    EXPECT_EQ(reports[i].second, 12u);
  }
  // The same call again, not cancelled: everything is built, and the count reaches the total.
  token.reset();
  reports.clear();
  control.progress = [&](std::size_t done, std::size_t total) { reports.emplace_back(done, total); };
  lib.buildAll(control);
  for (const ObjectId id : ids) EXPECT_TRUE(lib.isBuilt(id));
  EXPECT_EQ(lib.buildCount(), 12u);
  ASSERT_EQ(reports.size(), 12u);
  EXPECT_EQ(reports.back(), (std::pair<std::size_t, std::size_t>{12, 12}));
  // A token cancelled before the call: nothing starts.
  const ObjectId late = lib.addDeferred("late", "mesh", [] { return tinyMeshObject("late"); });
  token.cancel();
  EXPECT_THROW(lib.buildAll(control), Cancelled);
  EXPECT_FALSE(lib.isBuilt(late));
}

}  // namespace
}  // namespace duplex
