// Traces one ray through the installed library: a unit quad, placed by a scaled instance, hit at
// a point whose t, u and v are exact. Exit status 0 only if the hit is right.

#include <duplex/accel/Affine.h>
#include <duplex/accel/QueryContext.h>
#include <duplex/accel/TopLevel.h>
#include <duplex/objects/MeshObject.h>
#include <duplex/objects/TriangleMesh.h>
#include <duplex/scenegraph/Scene.h>

#include <cstdint>
#include <iostream>
#include <memory>

int main() {
  const float positions[] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
  const std::uint32_t indices[] = {0, 1, 2, 0, 2, 3};
  auto mesh = std::make_shared<const duplex::TriangleMesh>(duplex::TriangleMesh::fromArrays(positions, indices, "quad"));

  duplex::Scene scene;
  const std::uint32_t quad = scene.addObject("quad", std::make_shared<const duplex::MeshObject>(mesh));
  scene.addInstance(quad, duplex::Affine::identity());
  // Object (x, y, z) -> world (2x + 3, 2y, 2z - 1).
  scene.addInstance(quad, duplex::Affine::fromRowMajor3x4({2, 0, 0, 3, 0, 2, 0, 0, 0, 0, 2, -1}));

  duplex::TopLevel top;
  top.build(scene.instanceDescs());
  duplex::Ray ray;
  ray.origin = {4.5f, 0.5f, 1.0f};  // above object point (0.75, 0.25) of instance 1
  ray.dir = {0.0f, 0.0f, -1.0f};
  duplex::QueryContext ctx;
  const duplex::Hit hit = top.intersect(ray, ctx);

  const bool ok = hit.valid() && hit.instance_id == 1 && hit.prim_id == 0 && hit.t == 2.0f && hit.u == 0.5f &&
                  hit.v == 0.25f;
  std::cout << (ok ? "ok: " : "wrong hit: ") << hit << " (expected t=2, u=0.5, v=0.25, prim=0, inst=1)\n";
  return ok ? 0 : 1;
}
