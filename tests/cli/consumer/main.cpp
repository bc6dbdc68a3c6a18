// Traces one ray through the installed library's public scene API (ObjectLibrary, SceneGraph,
// SceneTracer): a unit quad, placed by a scaled instance, hit at a point whose t, u and v are exact.
// Also includes SceneDocument.h, whose headers use nlohmann_json (found by duplexConfig.cmake).
// Exit status 0 only if the hit is right and the built-in object types are registered.

#include <duplex/accel/Affine.h>
#include <duplex/accel/Hit.h>
#include <duplex/accel/QueryContext.h>
#include <duplex/accel/Ray.h>
#include <duplex/objects/BuiltinTypes.h>
#include <duplex/objects/MeshObject.h>
#include <duplex/objects/TriangleMesh.h>
#include <duplex/scenegraph/ObjectLibrary.h>
#include <duplex/scenegraph/ObjectTypeRegistry.h>
#include <duplex/scenegraph/SceneDocument.h>
#include <duplex/scenegraph/SceneGraph.h>
#include <duplex/scenegraph/SceneTracer.h>

#include <cstdint>
#include <iostream>
#include <memory>

int main() {
  const float positions[] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
  const std::uint32_t indices[] = {0, 1, 2, 0, 2, 3};
  auto mesh =
      std::make_shared<const duplex::TriangleMesh>(duplex::TriangleMesh::fromArrays(positions, indices, "quad"));

  auto library = std::make_shared<duplex::ObjectLibrary>();
  const duplex::ObjectId quad = library->add("quad", std::make_shared<const duplex::MeshObject>(mesh));
  duplex::SceneGraph graph(library);
  (void)graph.addInstance(duplex::kRootNode, quad, duplex::Affine::identity(), "plain");
  // Object (x, y, z) -> world (2x + 3, 2y, 2z - 1).
  const duplex::NodeId scaled = graph.addInstance(
      duplex::kRootNode, quad, duplex::Affine::fromRowMajor3x4({2, 0, 0, 3, 0, 2, 0, 0, 0, 0, 2, -1}), "scaled");
  (void)graph.commit();

  const duplex::SceneTracer tracer(graph);
  duplex::Ray ray;
  ray.origin = {4.5f, 0.5f, 1.0f};  // above object point (0.75, 0.25) of the scaled instance
  ray.dir = {0.0f, 0.0f, -1.0f};
  duplex::QueryContext ctx;
  const duplex::Hit hit = tracer.intersect(ray, ctx);

  const bool ok =
      hit.valid() && hit.instance_id == scaled && hit.prim_id == 0 && hit.t == 2.0f && hit.u == 0.5f && hit.v == 0.25f;
  std::cout << (ok ? "ok: " : "wrong hit: ") << hit << " (expected t=2, u=0.5, v=0.25, prim=0, inst=" << scaled
            << ")\n";
  // The scene-file readers are there too (ObjectTypeRegistry's readers take nlohmann::json specs).
  const bool types = duplex::builtinObjectTypes().find("mesh") != nullptr;
  if (!types) std::cout << "no built-in \"mesh\" object type\n";
  return ok && types ? 0 : 1;
}
