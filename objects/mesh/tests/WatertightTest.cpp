// Watertightness of MeshObject on closed meshes: rays aimed exactly at shared vertices and edges
// from outside, each from a direction that faces every triangle around its target, must hit, and
// never beyond the target, for the kd-tree and the BVH. 10^6 rays over the generated spheres alone
// (plus spot when the shared data is present).
//
// Near the origin the ray is built in double and rounded (origin, then direction = target - origin),
// so it passes within a computed distance delta of the target; the allowed t is widened by
// delta / (|dir| * min cos) where min cos is the smallest |d.n| over the target's triangles.
// Far from the origin the ray is exact: the mesh is scaled and moved so that every coordinate lies
// in [65536, 131072) and snapped to multiples of 1/16, so vertices and the points a + k/8 (b - a)
// on edges are floats, origin = float(target - dir0 * dist) stays in the same binade, and
// dir = target - origin is exact in float (Sterbenz): the ray passes exactly through the target
// at t = 1.

#include "MeshChecks.h"
#include "Reference.h"
#include "TestSupport.h"

#include "duplex/objects/MeshObject.h"

#include <gtest/gtest.h>
#include <glm/geometric.hpp>

#include <algorithm>
#include <cmath>
#include <map>
#include <random>
#include <vector>

namespace duplex::test {
namespace {

/// A point on the surface and the triangles around it (all incident to the vertex or the edge).
struct Target {
  glm::dvec3 point;
  std::vector<std::uint32_t> triangles;
  bool vertex;
};

/// Outward unit normals (the mesh's winding, flipped when its signed volume is negative).
std::vector<glm::dvec3> outwardNormals(const TriangleMesh& m) {
  const double sign = signedVolume(m) > 0.0 ? 1.0 : -1.0;
  std::vector<glm::dvec3> n(m.triangleCount(), glm::dvec3(0.0));
  for (std::size_t i = 0; i < m.triangleCount(); ++i) {
    if (!m.isValid(i)) continue;
    const auto v = m.vertices(i);
    n[i] = sign * glm::normalize(glm::cross(glm::dvec3(v[1]) - glm::dvec3(v[0]), glm::dvec3(v[2]) - glm::dvec3(v[0])));
  }
  return n;
}

/// Every vertex, and points on every manifold edge (two incident triangles): the `edge_points`
/// points a + k / (edge_points + 1) * (b - a), k = 1..edge_points. Non-manifold edges are counted.
std::vector<Target> surfaceTargets(const TriangleMesh& m, int edge_points, std::size_t& non_manifold_edges) {
  std::vector<std::vector<std::uint32_t>> vertex_tris(m.positions().size());
  std::map<std::pair<std::uint32_t, std::uint32_t>, std::vector<std::uint32_t>> edge_tris;
  for (std::size_t i = 0; i < m.triangleCount(); ++i) {
    if (!m.isValid(i)) continue;
    const auto& t = m.triangles()[i];
    for (int k = 0; k < 3; ++k) {
      vertex_tris[t[k]].push_back(static_cast<std::uint32_t>(i));
      edge_tris[std::minmax(t[k], t[(k + 1) % 3])].push_back(static_cast<std::uint32_t>(i));
    }
  }
  std::vector<Target> targets;
  for (std::size_t v = 0; v < vertex_tris.size(); ++v)
    if (vertex_tris[v].size() >= 3) targets.push_back({glm::dvec3(m.positions()[v]), vertex_tris[v], true});
  non_manifold_edges = 0;
  for (const auto& [edge, tris] : edge_tris) {
    if (tris.size() != 2) {
      ++non_manifold_edges;
      continue;
    }
    const glm::dvec3 a(m.positions()[edge.first]), b(m.positions()[edge.second]);
    for (int k = 1; k <= edge_points; ++k)
      targets.push_back({a + (static_cast<double>(k) / (edge_points + 1)) * (b - a), tris, false});
  }
  return targets;
}

/// Smallest -d.n over the target's triangles (positive: d faces all of them), d normalised.
double minFacing(const glm::dvec3& d, const Target& target, const std::vector<glm::dvec3>& normals) {
  const glm::dvec3 u = glm::normalize(d);
  double m = 1.0;
  for (const std::uint32_t t : target.triangles) m = std::min(m, -glm::dot(u, normals[t]));
  return m;
}

/// A unit direction facing every triangle of the target with margin: the negated mean normal,
/// perturbed at random (less on later attempts). False when no attempt works (a saddle vertex).
bool chooseDirection(const Target& target, const std::vector<glm::dvec3>& normals, std::mt19937_64& rng,
                     glm::dvec3& dir) {
  glm::dvec3 mean(0.0);
  for (const std::uint32_t t : target.triangles) mean += normals[t];
  if (glm::length(mean) == 0.0) return false;
  mean = glm::normalize(mean);
  std::normal_distribution<double> g(0.0, 1.0);
  for (int attempt = 0; attempt < 8; ++attempt) {
    const double amount = attempt < 4 ? 0.4 : (attempt < 7 ? 0.1 : 0.0);
    dir = glm::normalize(-mean + amount * draw3<glm::dvec3>(g, rng));
    if (minFacing(dir, target, normals) > 0.05) return true;
  }
  return false;
}

/// Draws targets in a shuffled cycle, each time with a fresh direction that faces all the target's
/// triangles; a target with no such direction (a saddle vertex) is skipped from then on and counted.
class TargetCycle {
 public:
  TargetCycle(std::vector<Target> targets, const std::vector<glm::dvec3>& normals, std::mt19937_64& rng)
      : targets_(std::move(targets)), normals_(normals), rng_(rng), unusable_(targets_.size(), 0) {
    std::shuffle(targets_.begin(), targets_.end(), rng_);
  }
  /// One draw: false when the drawn target has no facing direction (the caller draws again).
  bool next(const Target*& target, glm::dvec3& dir) {
    const std::size_t k = draws_++ % targets_.size();
    if (unusable_[k]) return false;
    if (!chooseDirection(targets_[k], normals_, rng_, dir)) {
      unusable_[k] = 1;
      ++skipped_;
      return false;
    }
    target = &targets_[k];
    return true;
  }
  /// Draws so far, the current one included.
  [[nodiscard]] std::size_t draws() const { return draws_; }
  [[nodiscard]] std::size_t skipped() const { return skipped_; }
  [[nodiscard]] std::size_t size() const { return targets_.size(); }

 private:
  std::vector<Target> targets_;
  const std::vector<glm::dvec3>& normals_;
  std::mt19937_64& rng_;
  std::vector<char> unusable_;
  std::size_t draws_ = 0, skipped_ = 0;
};

struct Tally {
  std::size_t rays = 0, misses = 0, beyond = 0, occlusion_failures = 0;
  double worst_excess = 0.0;  // largest (t - allowed) seen, for the failure message
};

void report(const Tally& s, std::size_t budget, const std::string& label) {
  EXPECT_EQ(s.rays, budget) << label;
  EXPECT_EQ(s.misses, 0u) << label << ": rays aimed at vertices/edges that missed the closed mesh";
  EXPECT_EQ(s.beyond, 0u) << label << ": first hits beyond the target (worst excess " << s.worst_excess << ")";
  EXPECT_EQ(s.occlusion_failures, 0u) << label << ": occluded() false up to the target";
}

/// Traces one ray that must hit with t <= t_allowed; counts and reports failures.
void traceOne(const MeshObject& object, const Ray& ray, double t_allowed, bool test_occlusion, const Target& target,
              Tally& s, const std::string& label) {
  ++s.rays;
  Hit hit;
  (void)object.intersect(ray, hit);
  if (!hit.valid()) {
    if (s.misses++ < 5)
      ADD_FAILURE() << label << ": " << ray << " aimed at " << (target.vertex ? "vertex" : "edge point") << " ("
                    << target.point.x << ", " << target.point.y << ", " << target.point.z << ") misses";
    return;
  }
  if (hit.t > t_allowed) {
    s.worst_excess = std::max(s.worst_excess, hit.t - t_allowed);
    if (s.beyond++ < 5)
      ADD_FAILURE() << label << ": " << ray << " aimed at " << (target.vertex ? "vertex" : "edge point") << " hits "
                    << hit << " beyond the target (allowed t <= " << t_allowed << ")";
  }
  if (test_occlusion) {
    Ray limited = ray;
    limited.tfar = static_cast<float>(t_allowed);
    if (static_cast<double>(limited.tfar) < t_allowed) limited.tfar = std::nextafter(limited.tfar, INFINITY);
    if (!object.occluded(limited) && s.occlusion_failures++ < 5)
      ADD_FAILURE() << label << ": occluded() false for " << limited << " aimed at the surface";
  }
}

/// float(v), kept out of the optimiser's sight: GCC 12 at -O2/-O3 (SLP vectorizer) was seen to
/// replace double(float(x)) by x in shootFarExact, i.e. to drop the rounding that the ray
/// construction relies on (clang and GCC -O1 keep it).
[[gnu::noinline]] glm::vec3 roundToFloat(const glm::dvec3& v) { return glm::vec3(v); }

/// Near the origin: rays built in double and rounded, tolerance from the computed miss distance.
void shootNearOrigin(std::shared_ptr<const TriangleMesh> mesh, const StructureCase& structure, std::size_t budget,
                     std::uint64_t seed, const std::string& label) {
  ASSERT_NE(signedVolume(*mesh), 0.0) << label << " encloses no volume";
  const auto object = buildChecked(mesh, structure.config);
  const auto normals = outwardNormals(*mesh);
  std::size_t non_manifold = 0;
  std::vector<Target> targets = surfaceTargets(*mesh, 3, non_manifold);
  ASSERT_FALSE(targets.empty());
  EXPECT_LT(non_manifold, mesh->triangleCount() / 100 + 1) << label << " should be a closed 2-manifold";
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  const double diag = glm::length(glm::dvec3(mesh->bounds().extent()));
  TargetCycle cycle(std::move(targets), normals, rng);
  Tally s;
  while (s.rays < budget) {
    ASSERT_LT(cycle.draws(), budget * 4) << label << ": too few usable targets";
    const Target* drawn = nullptr;
    glm::dvec3 dir0;
    if (!cycle.next(drawn, dir0)) continue;
    const Target& target = *drawn;
    const bool test_occlusion = (cycle.draws() - 1) % 3 == 0;
    const double dist = diag * (0.05 + 0.45 * u01(rng));
    Ray ray;
    ray.origin = roundToFloat(target.point - dir0 * dist);
    ray.dir = roundToFloat(target.point - glm::dvec3(ray.origin));
    const double facing = minFacing(glm::dvec3(ray.dir), target, normals);
    if (!(facing > 0.0)) continue;  // rounding turned the direction: draw again
    const glm::dvec3 o(ray.origin), d(ray.dir);
    const double t_star = glm::dot(target.point - o, d) / glm::dot(d, d);
    const double delta = glm::length(o + t_star * d - target.point);
    const double t_allowed = t_star * (1.0 + 1e-5) + 4.0 * delta / (glm::length(d) * facing);
    traceOne(*object, ray, t_allowed, test_occlusion, target, s, label);
  }
  EXPECT_LT(cycle.skipped(), cycle.size() / 50 + 1) << label << ": targets without a facing direction";
  report(s, budget, label);
}

/// The mesh scaled and moved into [65536, 131072)^3 (centre 98304, extent about 30000) and snapped
/// to multiples of 1/16.
TriangleMesh farFromOrigin(const TriangleMesh& m) {
  const Box b = m.bounds();
  const glm::dvec3 centre = 0.5 * (glm::dvec3(b.lo) + glm::dvec3(b.hi));
  const double extent = std::max({double(b.extent().x), double(b.extent().y), double(b.extent().z)});
  const double scale = 30000.0 / extent;
  std::vector<glm::vec3> p;
  for (const glm::vec3& q : m.positions()) {
    const glm::dvec3 x = 98304.0 + scale * (glm::dvec3(q) - centre);
    p.emplace_back(glm::round(x * 16.0) / 16.0);
  }
  return TriangleMesh::fromTriangles(std::move(p), m.triangles(), m.name() + " (far)");
}

/// Far from the origin: exact rays through the target at t = 1.
void shootFarExact(const TriangleMesh& original, const StructureCase& structure, std::size_t budget, std::uint64_t seed,
                   const std::string& label) {
  auto mesh = std::make_shared<const TriangleMesh>(farFromOrigin(original));
  ASSERT_EQ(mesh->degenerateCount(), original.degenerateCount()) << "snapping made triangles degenerate";
  for (int k = 0; k < 3; ++k) {
    ASSERT_GE(mesh->bounds().lo[k], 65536.0f);
    ASSERT_LT(mesh->bounds().hi[k], 131072.0f);
  }
  const auto object = buildChecked(mesh, structure.config);
  const auto normals = outwardNormals(*mesh);
  std::size_t non_manifold = 0;
  std::vector<Target> targets = surfaceTargets(*mesh, 7, non_manifold);
  for (const Target& t : targets)
    ASSERT_EQ(glm::dvec3(glm::vec3(t.point)), t.point) << "edge point not exactly a float";
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  TargetCycle cycle(std::move(targets), normals, rng);
  Tally s;
  while (s.rays < budget) {
    ASSERT_LT(cycle.draws(), budget * 4) << label << ": too few usable targets";
    const Target* drawn = nullptr;
    glm::dvec3 dir0;
    if (!cycle.next(drawn, dir0)) continue;
    const Target& target = *drawn;
    const bool test_occlusion = (cycle.draws() - 1) % 3 == 0;
    const double dist = 300.0 + 14000.0 * u01(rng);
    Ray ray;
    ray.origin = roundToFloat(target.point - dir0 * dist);
    bool same_binade = true;
    for (int k = 0; k < 3; ++k) same_binade = same_binade && ray.origin[k] >= 65536.0f && ray.origin[k] < 131072.0f;
    if (!same_binade) continue;
    ray.dir = glm::vec3(target.point) - ray.origin;  // exact (Sterbenz)
    ASSERT_EQ(glm::dvec3(ray.origin) + glm::dvec3(ray.dir), target.point) << "ray construction not exact: " << ray;
    const double facing = minFacing(glm::dvec3(ray.dir), target, normals);
    if (!(facing > 0.0)) continue;
    traceOne(*object, ray, 1.0 + 1e-5, test_occlusion, target, s, label);
  }
  EXPECT_LT(cycle.skipped(), cycle.size() / 50 + 1) << label << ": targets without a facing direction";
  report(s, budget, label);
}

// The generated closed meshes are what the tests assume: every edge shared by exactly two
// triangles with opposite directions (consistent winding), outward orientation, the right volume.
TEST(Generators, ClosedMeshesAreConsistentlyOutwardOriented) {
  const double pi = 3.14159265358979;
  struct Case {
    TriangleMesh mesh;
    double volume, rel_tol;
  };
  std::vector<Case> cases;
  cases.push_back({uvSphere(64, 32), 4.0 / 3.0 * pi, 0.02});
  cases.push_back({icosphere(4, 1.0, glm::dvec3(0.3, -0.2, 0.1)), 4.0 / 3.0 * pi, 0.02});
  cases.push_back({boxMesh(glm::vec3(-1.0f, -0.5f, 0.0f), glm::vec3(1.0f, 0.5f, 2.0f)), 4.0, 1e-12});
  for (const Case& c : cases) {
    SCOPED_TRACE(c.mesh.name());
    EXPECT_EQ(c.mesh.degenerateCount(), 0u);
    std::map<std::pair<std::uint32_t, std::uint32_t>, int> directed;
    for (const auto& t : c.mesh.triangles())
      for (int k = 0; k < 3; ++k) ++directed[{t[k], t[(k + 1) % 3]}];
    for (const auto& [edge, count] : directed) {
      EXPECT_EQ(count, 1) << "directed edge used twice";
      EXPECT_EQ(directed.count({edge.second, edge.first}), 1u) << "edge without an opposite twin";
    }
    EXPECT_NEAR(signedVolume(c.mesh), c.volume, c.rel_tol * c.volume);
  }
}

// Per structure 150k + 150k + 100k + 100k rays on the generated spheres: 10^6 over the kd-tree and
// the BVH (whose box test is what differs; its presets share it); spot adds 2 * 10^5 per structure.
// Each SIMD path of the BVH runs its own 5 * 10^5 (ctest's ISA variants).

class Watertight : public ::testing::TestWithParam<StructureCase> {
 protected:
  [[nodiscard]] std::string label(const std::string& what) const { return what + " / " + GetParam().name; }
};

TEST_P(Watertight, UvSphereNearOrigin) {
  auto mesh = std::make_shared<const TriangleMesh>(uvSphere(64, 32));
  ASSERT_GT(signedVolume(*mesh), 0.0);
  shootNearOrigin(mesh, GetParam(), 150000, 1, label("uv sphere"));
}

TEST_P(Watertight, UvSphereFarFromOriginExact) {
  shootFarExact(uvSphere(64, 32), GetParam(), 150000, 2, label("uv sphere far"));
}

TEST_P(Watertight, IcosphereNearOrigin) {
  auto mesh = std::make_shared<const TriangleMesh>(icosphere(4, 1.0, glm::dvec3(0.3, -0.2, 0.1)));
  ASSERT_GT(signedVolume(*mesh), 0.0);
  shootNearOrigin(mesh, GetParam(), 100000, 3, label("icosphere"));
}

TEST_P(Watertight, IcosphereFarFromOriginExact) {
  shootFarExact(icosphere(4), GetParam(), 100000, 4, label("icosphere far"));
}

TEST_P(Watertight, SpotNearOrigin) {
  DUPLEX_SHARED_MESH_OR_SKIP(mesh, "spot.obj");
  shootNearOrigin(mesh, GetParam(), 100000, 5, label("spot"));
}

TEST_P(Watertight, SpotFarFromOriginExact) {
  DUPLEX_SHARED_MESH_OR_SKIP(mesh, "spot.obj");
  shootFarExact(*mesh, GetParam(), 100000, 6, label("spot far"));
}

INSTANTIATE_TEST_SUITE_P(Structures, Watertight, ::testing::ValuesIn(defaultStructureCases()),
                         [](const auto& info) { return info.param.name; });

}  // namespace
}  // namespace duplex::test
