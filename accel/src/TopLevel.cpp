#include "duplex/accel/TopLevel.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/KdTraversal.h"
#include "duplex/accel/KdTreeBuilder.h"

#include <glm/matrix.hpp>

#include <string>

namespace duplex {

void TopLevel::build(std::span<const InstanceDesc> instances, const KdBuildConfig& config) {
  std::vector<std::shared_ptr<const Object>> owners;
  std::vector<Instance> items;
  std::vector<Box> boxes;
  owners.reserve(instances.size());
  items.reserve(instances.size());
  boxes.reserve(instances.size());
  for (const InstanceDesc& d : instances) {
    if (!d.object) throw InvalidArgument("instance " + std::to_string(d.id) + ": no object");
    if (!d.world_from_object.isFinite())
      throw InvalidArgument("instance " + std::to_string(d.id) + " (object '" + d.object->name() +
                            "'): transform has NaN or infinite entries");
    if (d.world_from_object.isSingular())
      throw InvalidArgument("instance " + std::to_string(d.id) + " (object '" + d.object->name() +
                            "'): transform is singular");
    owners.push_back(d.object);
    // Cofactor matrix det(L) L^-T: maps cross(v1 - v0, v2 - v0) of object space exactly to the
    // same cross product of the world-space vertices (the inverse transpose alone would lose the
    // scale and flip the winding of mirrored instances).
    const glm::dmat3& l = d.world_from_object.linear;
    const glm::dmat3 normal = glm::determinant(l) * glm::transpose(glm::inverse(l));
    const bool identity = d.world_from_object.linear == glm::dmat3(1.0) && d.world_from_object.translation == glm::dvec3(0.0);
    items.push_back({d.object.get(), d.world_from_object.inverse(), glm::mat3(normal), d.id, identity});
    boxes.push_back(d.world_from_object.apply(d.object->bounds()));
  }
  tree_ = buildKdTreeOverBoxes(boxes, config);
  owners_ = std::move(owners);
  instances_ = std::move(items);
}

Hit TopLevel::intersect(const Ray& ray_ws, QueryContext& ctx) const {
  ++ctx.stats.rays;
  if (!isQueryable(ray_ws)) return Hit{};
  Hit best;
  best.t = ray_ws.tfar;
  const Instance* winner = nullptr;
  // A small mailbox: an instance box usually spans several leaves, and a repeated bottom-level
  // traversal of the same instance for the same ray is wasted work.
  std::uint32_t mailbox[8];
  int mail_count = 0, mail_next = 0;
  const KdRay kray(ray_ws);
  float t_best = ray_ws.tfar;
  traverseKdTree<false>(tree_, kray, t_best, [&](std::uint32_t begin, std::uint32_t count, float& t) {
    bool found = false;
    for (std::uint32_t i = begin; i < begin + count; ++i) {
      const std::uint32_t index = tree_.prim_indices[i];
      bool seen = false;
      for (int m = 0; m < mail_count; ++m) seen |= mailbox[m] == index;
      if (seen) continue;
      mailbox[mail_next] = index;
      mail_next = (mail_next + 1) & 7;
      if (mail_count < 8) ++mail_count;
      const Instance& inst = instances_[index];
      ++ctx.stats.instance_visits;
      Ray ray_os = inst.identity ? ray_ws : inst.object_from_world.apply(ray_ws);
      ray_os.tfar = t;
      Hit h = best;
      h.t = t;
      if (inst.object->intersect(ray_os, h, ctx)) {
        best = h;
        t = h.t;
        winner = &inst;
        found = true;
      }
    }
    return found;
  });
  if (!winner) return Hit{};
  best.instance_id = winner->id;
  if (!winner->identity) best.ng = winner->normal_to_world * best.ng;
  return best;
}

bool TopLevel::occluded(const Ray& ray_ws, QueryContext& ctx) const {
  ++ctx.stats.rays;
  if (!isQueryable(ray_ws)) return false;
  const KdRay kray(ray_ws);
  float t_best = ray_ws.tfar;
  return traverseKdTree<true>(tree_, kray, t_best, [&](std::uint32_t begin, std::uint32_t count, float&) {
    for (std::uint32_t i = begin; i < begin + count; ++i) {
      const Instance& inst = instances_[tree_.prim_indices[i]];
      if (!inst.object->blocks()) continue;
      ++ctx.stats.instance_visits;
      const Ray ray_os = inst.identity ? ray_ws : inst.object_from_world.apply(ray_ws);
      if (inst.object->occluded(ray_os, ctx)) return true;
    }
    return false;
  });
}

}  // namespace duplex
