// Tolerance picking (SceneTracer::pickElement) and rectangle selection by geometry
// (SceneTracer::selectRectangle with RegionMode::Touching / Inside), for both mesh structures:
// hand-placed cases (vertex before edge before face, hidden elements, masks, hidden nodes, the
// feature filter) and randomized scenes against screen-space brute forces over every triangle.

#include "MeshChecks.h"
#include "TestSupport.h"
#include "TwoLevelChecks.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/RayGenerator.h"
#include "duplex/scenegraph/SceneGraph.h"
#include "duplex/scenegraph/SceneTracer.h"

#include <gtest/gtest.h>
#include <glm/geometric.hpp>
#include <glm/vec2.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <numbers>
#include <optional>
#include <random>
#include <set>
#include <tuple>
#include <vector>

namespace duplex::test {
namespace {

constexpr std::uint32_t kW = 400, kH = 300;

/// A camera at `eye` looking at `target`, up = +y, orthonormal axes.
PinholeCamera lookAt(const glm::dvec3& eye, const glm::dvec3& target) {
  PinholeCamera c;
  c.eye = eye;
  c.forward = glm::normalize(target - eye);
  c.right = glm::normalize(glm::cross(c.forward, glm::dvec3(0, 1, 0)));
  c.up = glm::cross(c.right, c.forward);
  c.vertical_fov_deg = 40.0;
  return c;
}

/// Pixel coordinates and depth along forward of world point p (independent of the library's own).
struct Projection {
  glm::dvec2 px;
  double z;
};
Projection project(const PinholeCamera& cam, const glm::dvec3& p) {
  const glm::dvec3 d = p - cam.eye;
  const double z = glm::dot(d, cam.forward);
  const double half_h = std::tan(0.5 * cam.vertical_fov_deg * std::numbers::pi / 180.0);
  const double half_w = half_h * kW / kH;
  return {{(glm::dot(d, cam.right) / z / half_w + 1.0) * 0.5 * kW, (1.0 - glm::dot(d, cam.up) / z / half_h) * 0.5 * kH},
          z};
}

/// A world-space triangle of a visible instance, with its ids.
struct WorldTriangle {
  NodeId instance;
  std::uint32_t prim;
  std::array<std::uint32_t, 3> v;
  std::array<glm::dvec3, 3> p;
};

/// Every valid triangle of every visible instance whose mask meets `mask`, through the graph.
std::vector<WorldTriangle> worldTriangles(const SceneGraph& g, std::uint32_t mask = 0xFFFFFFFFu) {
  std::vector<WorldTriangle> out;
  for (const NodeId id : g.visibleInstances()) {
    const NodeInfo info = g.node(id);
    if ((info.mask & mask) == 0) continue;
    const auto* mesh_object = dynamic_cast<const MeshObject*>(g.library().get(info.object).get());
    if (!mesh_object) continue;
    const TriangleMesh& m = mesh_object->mesh();
    const Affine& w = g.worldTransform(id);
    for (std::uint32_t t = 0; t < m.triangleCount(); ++t) {
      if (!m.isValid(t)) continue;
      WorldTriangle wt{id, t, m.triangles()[t], {}};
      for (int k = 0; k < 3; ++k) wt.p[k] = w.point(glm::dvec3(m.positions()[wt.v[k]]));
      out.push_back(wt);
    }
  }
  return out;
}

/// Moller-Trumbore in double: the ray parameter of the hit, if any, in (0, tmax).
std::optional<double> segmentHit(const glm::dvec3& o, const glm::dvec3& d, const WorldTriangle& t, double tmax) {
  const glm::dvec3 e1 = t.p[1] - t.p[0], e2 = t.p[2] - t.p[0], q = glm::cross(d, e2);
  const double det = glm::dot(e1, q);
  if (std::abs(det) < 1e-300) return std::nullopt;
  const glm::dvec3 s = o - t.p[0];
  const double u = glm::dot(s, q) / det;
  const glm::dvec3 r = glm::cross(s, e1);
  const double v = glm::dot(d, r) / det, h = glm::dot(e2, r) / det;
  if (u < 0 || v < 0 || u + v > 1 || !(h > 0 && h < tmax)) return std::nullopt;
  return h;
}

bool bruteVisible(const std::vector<WorldTriangle>& tris, const glm::dvec3& eye, const glm::dvec3& p) {
  for (const WorldTriangle& t : tris)
    if (segmentHit(eye, p - eye, t, 1.0 - 1e-4)) return false;
  return true;
}

/// Distance from c to the 2D segment [a, b].
double segmentDistance(const glm::dvec2& c, const glm::dvec2& a, const glm::dvec2& b) {
  const glm::dvec2 ab = b - a;
  const double l2 = glm::dot(ab, ab);
  const double s = l2 > 0 ? std::clamp(glm::dot(c - a, ab) / l2, 0.0, 1.0) : 0.0;
  return glm::length(a + s * ab - c);
}

class SceneTracerPick : public ::testing::TestWithParam<StructureCase> {
 protected:
  std::shared_ptr<ObjectLibrary> library = std::make_shared<ObjectLibrary>();
  SceneGraph graph{library};
  ObjectId add(const std::string& name, TriangleMesh mesh) {
    return library->add(name, buildChecked(std::make_shared<const TriangleMesh>(std::move(mesh)), GetParam().config));
  }
};

TEST_P(SceneTracerPick, VertexBeforeEdgeBeforeFace) {
  const ObjectId box = add("box", boxMesh(glm::vec3(-1.0f), glm::vec3(1.0f)));
  const Affine place = Affine::fromRowMajor3x4(
      rotationScaleTranslation(glm::dvec3(0.3, 1.0, 0.2), 0.4, glm::dvec3(1.0, 0.7, 1.3), glm::dvec3(0.2, 0.1, -0.3)));
  const NodeId inst = graph.addInstance(kRootNode, box, place, "box");
  graph.commit();
  SceneTracer tracer(graph);
  const PinholeCamera cam = lookAt(glm::dvec3(4.0, 3.0, 5.0), glm::dvec3(0.2, 0.1, -0.3));
  const TriangleMesh& m = dynamic_cast<const MeshObject&>(*library->get(box)).mesh();
  std::vector<glm::dvec3> v_ws;
  for (const glm::vec3& p : m.positions()) v_ws.push_back(place.point(glm::dvec3(p)));
  // The corner nearest the eye is visible (a convex box seen from outside).
  std::uint32_t front = 0;
  for (std::uint32_t i = 1; i < v_ws.size(); ++i)
    if (glm::length(v_ws[i] - cam.eye) < glm::length(v_ws[front] - cam.eye)) front = i;
  const glm::dvec2 at = project(cam, v_ws[front]).px;

  ElementPick p = tracer.pickElement(cam, at.x + 2.0, at.y + 1.0, kW, kH);
  ASSERT_EQ(p.kind, PickElement::Vertex);
  EXPECT_EQ(p.instance, inst);
  EXPECT_EQ(p.path, (std::vector<NodeId>{inst}));
  EXPECT_EQ(p.vertex, front);
  EXPECT_NEAR(p.distance_px, std::sqrt(5.0), 1e-6);
  EXPECT_LT(glm::length(p.point_ws - v_ws[front]), 1e-9);
  EXPECT_NEAR(p.depth, glm::length(v_ws[front] - cam.eye), 1e-9);
  const auto& t = m.triangles()[p.prim_id];
  EXPECT_TRUE(t[0] == front || t[1] == front || t[2] == front);

  // A box edge from the front corner (the neighbour differs in one coordinate bit): cursor 2 px
  // off its projected midpoint, perpendicular to it.
  const std::uint32_t next = front ^ 1u;
  const glm::dvec2 a = project(cam, v_ws[front]).px, b = project(cam, v_ws[next]).px;
  const glm::dvec2 along = glm::normalize(b - a), normal(-along.y, along.x);
  const glm::dvec2 mid = project(cam, 0.5 * (v_ws[front] + v_ws[next])).px + 2.0 * normal;
  p = tracer.pickElement(cam, mid.x, mid.y, kW, kH);
  ASSERT_EQ(p.kind, PickElement::Edge);
  EXPECT_EQ(p.edge, (std::array<std::uint32_t, 2>{std::min(front, next), std::max(front, next)}));
  EXPECT_NEAR(p.distance_px, 2.0, 1e-6);
  const glm::dvec3 e = v_ws[next] - v_ws[front];
  EXPECT_LT(glm::length(glm::cross(p.point_ws - v_ws[front], e)) / glm::length(e), 1e-9);  // on the edge
  EXPECT_NEAR(glm::length(project(cam, p.point_ws).px - mid), 2.0, 1e-6);

  // Priority: near a corner the incident edges are nearer on screen than the corner itself, yet
  // the vertex wins; without vertices the edge does.
  const glm::dvec2 near_corner = at + 3.0 * glm::normalize(along + 0.3 * normal);
  p = tracer.pickElement(cam, near_corner.x, near_corner.y, kW, kH);
  ASSERT_EQ(p.kind, PickElement::Vertex);
  PickOptions no_vertices;
  no_vertices.vertices = false;
  const ElementPick edge = tracer.pickElement(cam, near_corner.x, near_corner.y, kW, kH, no_vertices);
  ASSERT_EQ(edge.kind, PickElement::Edge);
  EXPECT_LT(edge.distance_px, p.distance_px);
  // Radius 0, or neither vertices nor edges: the face under the cursor, as pick() finds it.
  PickOptions faces_only;
  faces_only.radius_px = 0.0;
  const std::vector<SceneHit> under = tracer.pick(cam, at.x + 2.0, at.y + 1.0, kW, kH);
  ASSERT_EQ(under.size(), 1u);
  p = tracer.pickElement(cam, at.x + 2.0, at.y + 1.0, kW, kH, faces_only);
  ASSERT_EQ(p.kind, PickElement::Face);
  EXPECT_EQ(p.prim_id, under[0].hit.prim_id);
  EXPECT_LT(glm::length(p.point_ws - under[0].position_ws), 1e-12);
  // Nothing at all: off the box, and no faces wanted.
  PickOptions nothing;
  nothing.faces = false;
  EXPECT_FALSE(tracer.pickElement(cam, 1.0, 1.0, kW, kH, nothing).valid());
  EXPECT_FALSE(tracer.pickElement(cam, 1.0, 1.0, kW, kH).valid());
}

TEST_P(SceneTracerPick, HiddenElementsMasksAndHiddenNodes) {
  const ObjectId box = add("box", boxMesh(glm::vec3(-1.0f), glm::vec3(1.0f)));
  const ObjectId small = add("small", boxMesh(glm::vec3(-0.05f), glm::vec3(0.05f)));
  const NodeId cube = graph.addInstance(kRootNode, box, Affine::identity(), "cube", 1u);
  const PinholeCamera cam = lookAt(glm::dvec3(3.0, 2.5, 4.0), glm::dvec3(0.0));
  // The corner (1, 1, 1) faces the eye; the far corner (-1, -1, -1) projects inside the silhouette.
  const glm::dvec3 front(1.0), back(-1.0);
  const std::uint32_t front_id = 7, back_id = 0;  // boxMesh numbers corners by their bits
  // An occluder halfway to the front corner, on the segment from the eye.
  const Affine halfway = Affine::fromRowMajor3x4(
      {1, 0, 0, 0.5 * (cam.eye.x + 1.0), 0, 1, 0, 0.5 * (cam.eye.y + 1.0), 0, 0, 1, 0.5 * (cam.eye.z + 1.0)});
  const NodeId occluder = graph.addInstance(kRootNode, small, halfway, "occluder", 2u);
  graph.commit();
  SceneTracer tracer(graph);
  const glm::dvec2 at_front = project(cam, front).px, at_back = project(cam, back).px;

  ElementPick p = tracer.pickElement(cam, at_back.x, at_back.y, kW, kH);
  EXPECT_FALSE(p.kind == PickElement::Vertex && p.vertex == back_id) << "the far corner is hidden by the box";
  EXPECT_EQ(p.instance, cube);

  p = tracer.pickElement(cam, at_front.x, at_front.y, kW, kH);
  EXPECT_FALSE(p.instance == cube && p.kind == PickElement::Vertex) << "the occluder hides the front corner";
  // A mask that leaves the occluder out: it neither offers elements nor hides any.
  PickOptions cube_only;
  cube_only.mask = 1u;
  p = tracer.pickElement(cam, at_front.x, at_front.y, kW, kH, cube_only);
  ASSERT_EQ(p.kind, PickElement::Vertex);
  EXPECT_EQ(p.instance, cube);
  EXPECT_EQ(p.vertex, front_id);
  // Hidden nodes are not in the scene for picking.
  graph.setVisible(occluder, false);
  graph.commit();
  p = tracer.pickElement(cam, at_front.x, at_front.y, kW, kH);
  ASSERT_EQ(p.kind, PickElement::Vertex);
  EXPECT_EQ(p.vertex, front_id);
  graph.setVisible(cube, false);
  graph.commit();
  EXPECT_FALSE(tracer.pickElement(cam, at_front.x, at_front.y, kW, kH).valid());
}

TEST_P(SceneTracerPick, FeatureAngleKeepsOnlyDesignEdges) {
  const ObjectId box = add("box", boxMesh(glm::vec3(-1.0f), glm::vec3(1.0f)));
  const ObjectId sphere = add("sphere", icosphere(3));
  const NodeId cube = graph.addInstance(kRootNode, box, Affine::identity(), "cube");
  const NodeId ball =
      graph.addInstance(kRootNode, sphere, Affine::fromRowMajor3x4({1, 0, 0, 4, 0, 1, 0, 0, 0, 0, 1, -6}), "ball");
  graph.commit();
  SceneTracer tracer(graph);
  const PinholeCamera cam = lookAt(glm::dvec3(0.5, 0.3, 6.0), glm::dvec3(0.0, 0.0, -2.0));
  PickOptions features;
  features.feature_angle_deg = 30.0;
  // The front face z = 1 of the box is split by a diagonal; its midpoint is the face's centre.
  const glm::dvec2 centre = project(cam, glm::dvec3(0.0, 0.0, 1.0)).px + glm::dvec2(1.0, 0.0);
  ElementPick p = tracer.pickElement(cam, centre.x, centre.y, kW, kH);
  ASSERT_EQ(p.kind, PickElement::Edge) << "every edge counts without the filter";
  EXPECT_EQ(p.instance, cube);
  p = tracer.pickElement(cam, centre.x, centre.y, kW, kH, features);
  ASSERT_EQ(p.kind, PickElement::Face) << "a coplanar diagonal is no design edge";
  // A box corner stays a feature vertex, a box edge a feature edge.
  const glm::dvec2 corner = project(cam, glm::dvec3(1.0, 1.0, 1.0)).px;
  p = tracer.pickElement(cam, corner.x + 1.0, corner.y, kW, kH, features);
  ASSERT_EQ(p.kind, PickElement::Vertex);
  EXPECT_EQ(p.vertex, 7u);
  const glm::dvec2 edge_mid = project(cam, glm::dvec3(0.0, 1.0, 1.0)).px + glm::dvec2(0.0, 1.5);
  p = tracer.pickElement(cam, edge_mid.x, edge_mid.y, kW, kH, features);
  ASSERT_EQ(p.kind, PickElement::Edge);
  EXPECT_EQ(p.edge, (std::array<std::uint32_t, 2>{6u, 7u}));
  // A smooth sphere has no design edge: the face; unfiltered, its tessellation's vertices.
  const glm::dvec2 ball_px = project(cam, glm::dvec3(4.0, 0.0, -5.0)).px;  // the ball's front
  p = tracer.pickElement(cam, ball_px.x, ball_px.y, kW, kH, features);
  ASSERT_EQ(p.kind, PickElement::Face);
  EXPECT_EQ(p.instance, ball);
  p = tracer.pickElement(cam, ball_px.x, ball_px.y, kW, kH);
  EXPECT_EQ(p.kind, PickElement::Vertex);
  EXPECT_EQ(p.instance, ball);
}

/// The feature edges of every visible instance's mesh as PickOptions::feature_angle_deg defines
/// them, by brute force over the object's own (object-space) triangles: keys (instance, low, high).
std::set<std::tuple<NodeId, std::uint32_t, std::uint32_t>> featureEdges(const SceneGraph& g, double feature_angle_deg) {
  std::set<std::tuple<NodeId, std::uint32_t, std::uint32_t>> out;
  for (const NodeId id : g.visibleInstances()) {
    const auto* mesh_object = dynamic_cast<const MeshObject*>(g.library().get(g.node(id).object).get());
    if (!mesh_object) continue;
    const TriangleMesh& m = mesh_object->mesh();
    std::map<std::pair<std::uint32_t, std::uint32_t>, std::vector<glm::dvec3>> faces;
    for (std::uint32_t t = 0; t < m.triangleCount(); ++t) {
      if (!m.isValid(t)) continue;
      const auto& v = m.triangles()[t];
      const glm::dvec3 a(m.positions()[v[0]]), b(m.positions()[v[1]]), c(m.positions()[v[2]]);
      const glm::dvec3 n = glm::normalize(glm::cross(b - a, c - a));
      for (int k = 0; k < 3; ++k) faces[{std::min(v[k], v[(k + 1) % 3]), std::max(v[k], v[(k + 1) % 3])}].push_back(n);
    }
    for (const auto& [edge, normals] : faces) {
      const bool feature = feature_angle_deg == 0.0 || normals.size() != 2 ||
                           std::acos(std::clamp(glm::dot(normals[0], normals[1]), -1.0, 1.0)) >
                               feature_angle_deg * std::numbers::pi / 180.0;
      if (feature) out.insert({id, edge.first, edge.second});
    }
  }
  return out;
}

/// 150 random picks with radius r against a screen-space brute force over every triangle (vertices
/// within r by screen distance and depth, the first visible one; then the nearest visible edge;
/// then the face under the cursor), only feature edges and their ends counting when
/// feature_angle_deg > 0. Counts the kinds found.
void expectRandomPicksAgree(const SceneTracer& tracer, const SceneGraph& graph, const PinholeCamera& cam,
                            double feature_angle_deg, std::mt19937_64& rng, int& vertices, int& edges, int& faces) {
  const auto features = featureEdges(graph, feature_angle_deg);
  const auto isFeature = [&](NodeId id, std::uint32_t a, std::uint32_t b) {
    return features.count({id, std::min(a, b), std::max(a, b)}) > 0;
  };
  PickOptions options{3.0};
  options.feature_angle_deg = feature_angle_deg;
  const std::vector<WorldTriangle> tris = worldTriangles(graph);
  const double r = options.radius_px;
  std::uniform_real_distribution<double> ux(0.0, kW), uy(0.0, kH), jitter(-3.0, 3.0), u01(0.0, 1.0);
  std::uniform_int_distribution<std::size_t> pick_tri(0, tris.size() - 1);
  for (int q = 0; q < 150; ++q) {
    // A third of the cursors near a projected vertex, a third inside a projected triangle, a
    // third anywhere.
    const double cx = ux(rng), cy = uy(rng);
    glm::dvec2 c(cx, cy);
    const WorldTriangle& aim = tris[pick_tri(rng)];
    if (q % 3 == 0) {
      const double dx = jitter(rng), dy = jitter(rng);
      c = project(cam, aim.p[0]).px + glm::dvec2(dx, dy);
    }
    if (q % 3 == 1) {
      const double b1 = u01(rng), b2 = u01(rng) * (1.0 - b1);
      c = project(cam, aim.p[0] + b1 * (aim.p[1] - aim.p[0]) + b2 * (aim.p[2] - aim.p[0])).px;
    }
    // Brute force: vertices within r by (screen distance, depth), the first visible one; then edges.
    using Cand = std::tuple<double, double, NodeId, std::uint32_t, std::uint32_t>;
    std::vector<Cand> vc, ec;
    for (const WorldTriangle& t : tris)
      for (int k = 0; k < 3; ++k) {
        if (!isFeature(t.instance, t.v[k], t.v[(k + 1) % 3])) continue;
        const Projection a = project(cam, t.p[k]), b = project(cam, t.p[(k + 1) % 3]);
        if (a.z <= 0 || b.z <= 0) continue;
        const double dv = glm::length(a.px - c);
        if (dv <= r) vc.emplace_back(dv, glm::length(t.p[k] - cam.eye), t.instance, t.v[k], kInvalidId);
        const double de = segmentDistance(c, a.px, b.px);
        if (de <= r)
          ec.emplace_back(de, 0.0, t.instance, std::min(t.v[k], t.v[(k + 1) % 3]), std::max(t.v[k], t.v[(k + 1) % 3]));
      }
    std::sort(vc.begin(), vc.end());
    ElementPick want;
    for (const Cand& v : vc) {
      const WorldTriangle* owner = nullptr;
      int corner = 0;
      for (const WorldTriangle& t : tris)
        for (int k = 0; k < 3 && !owner; ++k)
          if (t.instance == std::get<2>(v) && t.v[k] == std::get<3>(v)) owner = &t, corner = k;
      if (!bruteVisible(tris, cam.eye, owner->p[corner])) continue;
      want.kind = PickElement::Vertex;
      want.instance = std::get<2>(v);
      want.vertex = std::get<3>(v);
      break;
    }
    const ElementPick got = tracer.pickElement(cam, c.x, c.y, kW, kH, options);
    if (want.kind == PickElement::Vertex) {
      ASSERT_EQ(got.kind, PickElement::Vertex) << "cursor " << c.x << ", " << c.y;
      EXPECT_EQ(got.instance, want.instance);
      EXPECT_EQ(got.vertex, want.vertex);
      ++vertices;
      continue;
    }
    ASSERT_NE(got.kind, PickElement::Vertex) << "cursor " << c.x << ", " << c.y << ": no visible vertex within r";
    // Edges: each one's point nearest the cursor on screen (the screen parameter taken back to the
    // edge with the perspective division: 1/depth is linear on screen), the nearest visible wins.
    double want_edge = std::numeric_limits<double>::infinity();
    for (const Cand& e : ec) {
      const WorldTriangle* owner = nullptr;
      for (const WorldTriangle& t : tris)
        if (t.instance == std::get<2>(e) && !owner)
          for (int k = 0; k < 3; ++k)
            if (t.v[k] == std::get<3>(e) && (t.v[(k + 1) % 3] == std::get<4>(e) || t.v[(k + 2) % 3] == std::get<4>(e)))
              owner = &t;
      ASSERT_NE(owner, nullptr);
      glm::dvec3 a, b;
      for (int k = 0; k < 3; ++k) {
        if (owner->v[k] == std::get<3>(e)) a = owner->p[k];
        if (owner->v[k] == std::get<4>(e)) b = owner->p[k];
      }
      const Projection pa = project(cam, a), pb = project(cam, b);
      const glm::dvec2 sab = pb.px - pa.px;
      const double l2 = glm::dot(sab, sab);
      const double s = l2 > 0 ? std::clamp(glm::dot(c - pa.px, sab) / l2, 0.0, 1.0) : 0.0;
      const double u = s * pa.z / ((1.0 - s) * pb.z + s * pa.z);
      const glm::dvec3 ab = b - a;
      if (bruteVisible(tris, cam.eye, a + u * ab)) want_edge = std::min(want_edge, std::get<0>(e));
    }
    if (want_edge <= r) {
      ASSERT_EQ(got.kind, PickElement::Edge) << "cursor " << c.x << ", " << c.y;
      EXPECT_NEAR(got.distance_px, want_edge, 1e-6);
      bool listed = false;
      for (const Cand& e : ec)
        listed = listed ||
                 (std::get<2>(e) == got.instance && std::get<3>(e) == got.edge[0] && std::get<4>(e) == got.edge[1]);
      EXPECT_TRUE(listed);
      ++edges;
      continue;
    }
    ASSERT_NE(got.kind, PickElement::Edge) << "cursor " << c.x << ", " << c.y << ": no visible edge within r";
    const std::vector<SceneHit> under = tracer.pick(cam, c.x, c.y, kW, kH);
    EXPECT_EQ(got.valid(), !under.empty());
    if (!under.empty()) {
      EXPECT_EQ(got.instance, under[0].instance);
      EXPECT_EQ(got.prim_id, under[0].hit.prim_id);
      ++faces;
    }
  }
}

TEST_P(SceneTracerPick, RandomPicksAgreeWithABruteForceOverEveryTriangle) {
  const ObjectId sphere = add("sphere", icosphere(1));
  const ObjectId box = add("box", boxMesh(glm::vec3(-1.0f), glm::vec3(1.0f)));
  std::mt19937_64 rng(21);
  for (int i = 0; i < 24; ++i) graph.addInstance(kRootNode, i % 2 ? sphere : box, randomPlacement(rng, 10.0));
  graph.commit();
  SceneTracer tracer(graph);
  int vertices = 0, edges = 0, faces = 0;
  expectRandomPicksAgree(tracer, graph, PinholeCamera::looking_at_box(tracer.bounds()), 0.0, rng, vertices, edges,
                         faces);
  EXPECT_GT(vertices, 20);
  EXPECT_GT(edges, 5);
  EXPECT_GT(faces, 5);
}

// The feature filter through each object's feature-edge index: boxes (diagonals filtered out),
// coarse and finer spheres (some neighbours above the angle, some below), an open grid (its border
// counts, its inside does not), under non-uniform scales, against the brute force.
TEST_P(SceneTracerPick, RandomFeaturePicksAgreeWithABruteForceOverEveryTriangle) {
  const ObjectId objects[] = {add("box", boxMesh(glm::vec3(-1.0f), glm::vec3(1.0f))), add("ico", icosphere(1)),
                              add("uv", uvSphere(10, 7)), add("grid", flatGrid(4))};
  std::mt19937_64 rng(22);
  for (int i = 0; i < 28; ++i) graph.addInstance(kRootNode, objects[i % 4], randomPlacement(rng, 10.0));
  graph.commit();
  SceneTracer tracer(graph);
  const PinholeCamera cam = PinholeCamera::looking_at_box(tracer.bounds());
  int vertices = 0, edges = 0, faces = 0;
  expectRandomPicksAgree(tracer, graph, cam, 30.0, rng, vertices, edges, faces);
  EXPECT_GT(vertices, 10);
  EXPECT_GT(edges, 5);
  EXPECT_GT(faces, 5);
  // After an edit (a moved instance and a replaced object: a new index, the old one let go).
  graph.setTransform(graph.visibleInstances().front(), randomPlacement(rng, 10.0));
  graph.replaceObject(objects[1], buildChecked(std::make_shared<const TriangleMesh>(icosphere(0)), GetParam().config));
  graph.commit();
  vertices = edges = faces = 0;
  expectRandomPicksAgree(tracer, graph, cam, 30.0, rng, vertices, edges, faces);
  EXPECT_GT(vertices + edges, 10);
}

TEST_P(SceneTracerPick, RectangleSelectionByGeometryAgreesWithAScreenSpaceReference) {
  const ObjectId sphere = add("sphere", icosphere(2));
  const ObjectId grid = add("grid", flatGrid(6, 2, 0.0f, 0.25f));
  const ObjectId soup = add("soup", triangleSoup(80, 7));
  std::mt19937_64 rng(8);
  std::vector<NodeId> all;
  for (int i = 0; i < 90; ++i) {
    const ObjectId o = i % 3 == 0 ? sphere : (i % 3 == 1 ? grid : soup);
    all.push_back(graph.addInstance(kRootNode, o, randomPlacement(rng, 30.0)));
  }
  graph.commit();
  SceneTracer tracer(graph);
  const PinholeCamera cam = lookAt(tracer.bounds().center() + glm::vec3(5.0f, 8.0f, 60.0f), tracer.bounds().center());
  const std::vector<WorldTriangle> tris = worldTriangles(graph);
  std::uniform_real_distribution<double> ux(0.0, kW), uy(0.0, kH);
  int differs = 0, inside_total = 0;
  for (int q = 0; q < 30; ++q) {
    double x0 = ux(rng), x1 = ux(rng), y0 = uy(rng), y1 = uy(rng);
    if (x0 > x1) std::swap(x0, x1);
    if (y0 > y1) std::swap(y0, y1);
    const auto in_rect = [&](const glm::dvec2& p) { return p.x >= x0 && p.x <= x1 && p.y >= y0 && p.y <= y1; };
    // A triangle in front of the eye meets the frustum iff an edge's projection meets the
    // rectangle or the rectangle lies inside the triangle's projection (its corner ray pierces it).
    const auto segmentMeetsRect = [&](glm::dvec2 a, glm::dvec2 b) {
      double t0 = 0.0, t1 = 1.0;  // Liang-Barsky
      const glm::dvec2 d = b - a;
      const double p[4] = {-d.x, d.x, -d.y, d.y}, qv[4] = {a.x - x0, x1 - a.x, a.y - y0, y1 - a.y};
      for (int i = 0; i < 4; ++i) {
        if (p[i] == 0.0) {
          if (qv[i] < 0.0) return false;
          continue;
        }
        const double t = qv[i] / p[i];
        if (p[i] < 0.0) t0 = std::max(t0, t);
        else t1 = std::min(t1, t);
      }
      return t0 <= t1;
    };
    const glm::dvec3 corner_ray = cam.directionAt(x0, y0, kW, kH);
    std::vector<NodeId> touching, inside;
    for (const NodeId id : all) {
      bool touches = false, all_in = true, any = false;
      for (const WorldTriangle& t : tris) {
        if (t.instance != id) continue;
        any = true;
        Projection pr[3];
        for (int k = 0; k < 3; ++k) pr[k] = project(cam, t.p[k]);
        ASSERT_TRUE(pr[0].z > 0 && pr[1].z > 0 && pr[2].z > 0) << "the reference needs everything in front";
        for (int k = 0; k < 3; ++k) all_in = all_in && in_rect(pr[k].px);
        if (!touches)
          touches = segmentMeetsRect(pr[0].px, pr[1].px) || segmentMeetsRect(pr[1].px, pr[2].px) ||
                    segmentMeetsRect(pr[2].px, pr[0].px) ||
                    segmentHit(cam.eye, corner_ray, t, std::numeric_limits<double>::infinity()).has_value();
      }
      if (touches) touching.push_back(id);
      if (any && all_in) inside.push_back(id);
    }
    EXPECT_EQ(tracer.selectRectangle(cam, x0, y0, x1, y1, kW, kH), touching) << "query " << q;
    EXPECT_EQ(tracer.selectRectangle(cam, x0, y0, x1, y1, kW, kH, 0xFFFFFFFFu, RegionMode::Inside), inside)
        << "query " << q;
    const std::vector<NodeId> boxes =
        tracer.selectRectangle(cam, x0, y0, x1, y1, kW, kH, 0xFFFFFFFFu, RegionMode::Boxes);
    EXPECT_TRUE(std::includes(boxes.begin(), boxes.end(), touching.begin(), touching.end())) << "query " << q;
    differs += boxes != touching;
    inside_total += static_cast<int>(inside.size());
  }
  EXPECT_GT(differs, 3);  // the geometric test matters: boxes select more
  EXPECT_GT(inside_total, 10);
}

TEST_P(SceneTracerPick, SelectionHonoursMasksAndHiddenNodes) {
  const ObjectId box = add("box", boxMesh(glm::vec3(-1.0f), glm::vec3(1.0f)));
  const NodeId a = graph.addInstance(kRootNode, box, Affine::identity(), "a", 1u);
  const NodeId b =
      graph.addInstance(kRootNode, box, Affine::fromRowMajor3x4({1, 0, 0, 0.5, 0, 1, 0, 0, 0, 0, 1, -3}), "b", 2u);
  graph.commit();
  SceneTracer tracer(graph);
  const PinholeCamera cam = lookAt(glm::dvec3(0.0, 0.0, 8.0), glm::dvec3(0.0));
  for (const RegionMode mode : {RegionMode::Boxes, RegionMode::Touching, RegionMode::Inside}) {
    EXPECT_EQ(tracer.selectRectangle(cam, 0, 0, kW, kH, kW, kH, 0xFFFFFFFFu, mode), (std::vector<NodeId>{a, b}));
    EXPECT_EQ(tracer.selectRectangle(cam, 0, 0, kW, kH, kW, kH, 2u, mode), (std::vector<NodeId>{b}));
  }
  graph.setVisible(a, false);
  graph.commit();
  EXPECT_EQ(tracer.selectRectangle(cam, 0, 0, kW, kH, kW, kH), (std::vector<NodeId>{b}));
}

TEST_P(SceneTracerPick, RefusesBadOptions) {
  const ObjectId box = add("box", boxMesh(glm::vec3(-1.0f), glm::vec3(1.0f)));
  graph.addInstance(kRootNode, box);
  graph.commit();
  SceneTracer tracer(graph);
  const PinholeCamera cam = lookAt(glm::dvec3(0.0, 0.0, 8.0), glm::dvec3(0.0));
  PickOptions o;
  for (const double bad : {-1.0, std::nan(""), std::numeric_limits<double>::infinity()}) {
    o.radius_px = bad;
    expectErrorNaming<InvalidArgument>([&] { (void)tracer.pickElement(cam, 10, 10, kW, kH, o); }, "radius_px");
  }
  o = {};
  for (const double bad : {-1.0, 180.0, std::nan("")}) {
    o.feature_angle_deg = bad;
    expectErrorNaming<InvalidArgument>([&] { (void)tracer.pickElement(cam, 10, 10, kW, kH, o); }, "feature_angle_deg");
  }
  expectErrorNaming<InvalidArgument>([&] { (void)tracer.pickElement(cam, std::nan(""), 10, kW, kH); }, "finite");
  expectErrorNaming<InvalidArgument>([&] { (void)tracer.pickElement(cam, 10, 10, 0, kH); }, "image size");
  PinholeCamera flat = cam;
  flat.forward = flat.right;  // right and up independent, forward in their plane: no projection
  expectErrorNaming<InvalidArgument>([&] { (void)tracer.pickElement(flat, 10, 10, kW, kH); }, "forward");
}

INSTANTIATE_TEST_SUITE_P(Structures, SceneTracerPick, ::testing::ValuesIn(defaultStructureCases()),
                         [](const auto& info) { return info.param.name; });

}  // namespace
}  // namespace duplex::test
