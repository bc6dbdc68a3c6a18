#pragma once
/// \file SlabMedium.h
/// A test medium (ObjectRole::Medium) of constant extinction sigma inside its box: transmittance
/// exp(-sigma * length of the ray inside the box), computed in double. Used by the sensor tests.

#include "duplex/accel/Object.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <cmath>
#include <string_view>
#include <utility>
#include <vector>

namespace duplex::test {

class SlabMedium final : public Object {
 public:
  SlabMedium(double sigma, Box box) : Object("slab", ObjectRole::Medium), sigma_(sigma), box_(box) {}
  std::string_view typeName() const override { return "slab"; }
  Box bounds() const override { return box_; }
  bool intersect(const Ray&, Hit&, QueryContext&) const override { return false; }
  bool occluded(const Ray&, QueryContext&) const override { return false; }
  void intersectAll(const Ray&, std::vector<Hit>&, QueryContext&) const override {}
  float transmittance(const Ray& r, QueryContext&) const override {
    double t0 = r.tnear, t1 = r.tfar;
    for (int k = 0; k < 3; ++k) {
      const double inv = 1.0 / r.dir[k];
      double a = (box_.lo[k] - r.origin[k]) * inv, b = (box_.hi[k] - r.origin[k]) * inv;
      if (a > b) std::swap(a, b);
      t0 = std::max(t0, a);
      t1 = std::min(t1, b);
    }
    const double len = std::max(0.0, t1 - t0) * glm::length(glm::dvec3(r.dir));
    return static_cast<float>(std::exp(-sigma_ * len));
  }
  std::size_t memoryBytes() const override { return sizeof(*this); }

 private:
  double sigma_;
  Box box_;
};

}  // namespace duplex::test
