// VolumeObject: OpenVDB float grids as level-set surfaces or fog media. The only library file that
// includes OpenVDB (slow to compile): everything OpenVDB stays behind VolumeObject::Grid.
//
// Tree walk: OpenVDB's hierarchical DDA (math::VolumeHDDA; Museth, "Hierarchical digital
// differential analyzer for efficient ray-marching in OpenVDB", SIGGRAPH 2014 talks) lists the
// spans of a ray that cross active leaves or tiles; inside a span, level sets are sampled every
// half voxel and fog densities are integrated voxel by voxel with a DDA (Amanatides and Woo 1987).
// We use our own per-thread accessor and index-space ray whose direction is NOT normalised (unlike
// openvdb::math::Ray::worldToIndex), so every time below is in units of the object-space ray's
// direction: no conversion of times is needed between object and index space.

#include "VolumeGrid.h"
#include "VdbFileCheck.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/InputFile.h"
#include "duplex/accel/Xxh64.h"

#include <openvdb/io/File.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tree/LeafManager.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <mutex>
#include <optional>
#include <sstream>
#include <vector>

namespace duplex {

using namespace volume_detail;

namespace {

// Entry level of the hierarchical DDA: the root's children (the upper internal nodes).
using HddaT = vdb::math::VolumeHDDA<TreeT, RayI, Upper::LEVEL>;

}  // namespace

namespace volume_detail {

void initializeOpenVdb() {
  static std::once_flag once;
  std::call_once(once, [] { vdb::initialize(); });
}

ThreadState& threadState(const void* key, const std::shared_ptr<const VolumeObject::Grid>& g, QueryContext& ctx) {
  ThreadState& s = ctx.cached<ThreadState>(key, [&] { return ThreadState(g); });
  if (s.data != g) s = ThreadState(g);
  return s;
}

bool indexRay(const VolumeObject::Grid& g, const Ray& ray_os, double tmin, double tmax, double shift, RayI& out) {
  if (!isQueryable(ray_os) || !(tmin <= tmax)) return false;
  const vdb::math::Transform& xf = g.grid->transform();
  vdb::Vec3d o = xf.worldToIndex(vdb::Vec3d(ray_os.origin.x, ray_os.origin.y, ray_os.origin.z));
  const vdb::Vec3d d = xf.baseMap()->applyInverseJacobian(vdb::Vec3d(ray_os.dir.x, ray_os.dir.y, ray_os.dir.z));
  o += vdb::Vec3d(shift);
  // Slab clip against the clip box (shifted alike); zero direction components need the origin inside.
  double t0 = tmin, t1 = tmax;
  for (int a = 0; a < 3; ++a) {
    const double lo = g.clip_min_is[a] + shift, hi = g.clip_max_is[a] + shift;
    if (d[a] == 0.0) {
      if (o[a] < lo || o[a] > hi) return false;
      continue;
    }
    const double inv = 1.0 / d[a];
    double ta = (lo - o[a]) * inv, tb = (hi - o[a]) * inv;
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  if (!(t0 <= t1) || !std::isfinite(t1)) return false;
  // A voxel must take a representable step of t: when the time to cross one (1 / the largest
  // direction component, in voxels) is below 1e-12 of t itself (an origin ~1e20 voxels away, or a
  // direction ~1e20 voxels long), the ray's position inside the grid is not determined by its
  // numbers, and the DDA could not advance (it would never return). Such a ray misses, as other
  // rays that cannot be traced do.
  const double fastest = std::max({std::abs(d[0]), std::abs(d[1]), std::abs(d[2])});
  if (fastest * std::max(std::abs(t0), std::abs(t1)) * 1e-12 > 1.0) return false;
  out = RayI(o, d, t0, t1);
  return true;
}

const std::vector<TimeSpan>& activeSpans(const RayI& ray, ThreadState& s) {
  RayI r = ray;  // the HDDA rewrites the ray's times
  HddaT hdda;
  hdda.hits(r, s.acc, s.spans);
  return s.spans;
}

}  // namespace volume_detail

std::string_view toString(VolumeKind kind) {
  switch (kind) {
    case VolumeKind::Auto: return "auto";
    case VolumeKind::LevelSet: return "levelset";
    case VolumeKind::Fog: return "fog";
  }
  return "?";
}

std::ostream& operator<<(std::ostream& os, VolumeKind kind) { return os << toString(kind); }

namespace {

double sampleIS(AccessorT& acc, const vdb::Vec3d& p_is) { return vdb::tools::BoxSampler::sample(acc, p_is); }

// Calls on(t) for each zero crossing of the interpolated level set along `ray` in order, until it
// returns true. Samples every half voxel inside the active spans; across the gaps between spans the
// distance is constant (background), so a sign change between the last sample before a gap and the
// first after it is refined over the gap. Refinement: bisection until the bracket is at most
// step / 2^refine_steps, then a secant step (config.levelset_step, config.refine_steps).
template <class OnCrossing>
void forEachCrossing(const RayI& ray, ThreadState& s, const VolumeQueryConfig& config, OnCrossing on) {
  const double dir_len = ray.dir().length();
  const double dt = config.levelset_step / dir_len;
  const double tol = std::ldexp(dt, -config.refine_steps);
  auto f = [&](double t) { return sampleIS(s.acc, ray(t)); };
  double tp = ray.t0();
  double fp = f(tp);
  auto visit = [&](double t) -> bool {  // true: stop
    const double ft = f(t);
    if ((ft < 0.0) != (fp < 0.0)) {
      double a = tp, fa = fp, b = t, fb = ft;
      while (b - a > tol) {
        const double m = 0.5 * (a + b), fm = f(m);
        if ((fm < 0.0) == (fa < 0.0)) {
          a = m;
          fa = fm;
        } else {
          b = m;
          fb = fm;
        }
      }
      const double tc = fa != fb ? std::clamp(a + (b - a) * fa / (fa - fb), a, b) : a;
      if (on(tc)) return true;
    }
    tp = t;
    fp = ft;
    return false;
  };
  for (const TimeSpan& span : activeSpans(ray, s)) {
    const double a = std::max(span.t0, ray.t0()), b = std::min(span.t1, ray.t1());
    if (!(a <= b)) continue;
    for (std::uint64_t k = 0;; ++k) {
      const double t = std::min(a + static_cast<double>(k) * dt, b);
      if (visit(t)) return;
      if (t >= b) break;
    }
  }
  if (tp < ray.t1()) (void)visit(ray.t1());
}

// Unit object-space normal at index-space point p: central differences of the interpolated
// distance (half a voxel apart), mapped by the inverse transpose of the index-to-object Jacobian.
glm::vec3 normalAt(const VolumeObject::Grid& g, AccessorT& acc, const vdb::Vec3d& p) {
  const double h = 0.5;
  const vdb::Vec3d grad_is(sampleIS(acc, p + vdb::Vec3d(h, 0, 0)) - sampleIS(acc, p - vdb::Vec3d(h, 0, 0)),
                           sampleIS(acc, p + vdb::Vec3d(0, h, 0)) - sampleIS(acc, p - vdb::Vec3d(0, h, 0)),
                           sampleIS(acc, p + vdb::Vec3d(0, 0, h)) - sampleIS(acc, p - vdb::Vec3d(0, 0, h)));
  vdb::Vec3d n = g.grid->transform().baseMap()->applyIJT(grad_is);
  const double len = n.length();
  if (!(len > 0.0) || !std::isfinite(len)) return glm::vec3(0.0f);
  n /= len;
  return glm::vec3(static_cast<float>(n.x()), static_cast<float>(n.y()), static_cast<float>(n.z()));
}

Hit crossingHit(const VolumeObject::Grid& g, AccessorT& acc, const RayI& ray, double t) {
  Hit h;
  h.t = static_cast<float>(t);
  h.u = h.v = 0.0f;
  h.prim_id = 0;
  h.ng = normalAt(g, acc, ray(t));
  return h;
}

std::string describeGrid(const std::string& where, const std::string& grid_name) {
  return where.empty() ? "grid \"" + grid_name + "\"" : where + ": grid \"" + grid_name + "\"";
}

void validate(const VolumeQueryConfig& c, const std::string& what) {
  auto bad = [&](const std::string& m) { throw InvalidArgument(what + ": query config: " + m); };
  if (c.samples < 1) bad("samples must be at least 1");
  if (!(c.march_step > 0.0) || !std::isfinite(c.march_step)) bad("march_step must be positive and finite");
  if (c.majorant_level < 0 || c.majorant_level >= kLevels) bad("majorant_level must be 0, 1 or 2");
  if (!(c.levelset_step > 0.0 && c.levelset_step <= 1.0)) bad("levelset_step must be in (0, 1] voxel");
  if (c.refine_steps < 0 || c.refine_steps > 60) bad("refine_steps must be in [0, 60]");
  switch (c.transmittance) {
    case FogMethod::Exact:
    case FogMethod::RatioTracking:
    case FogMethod::DeltaTracking:
    case FogMethod::RayMarching: break;
    default: bad("unknown transmittance method");
  }
}

// Density range (effective values) over one node, inactive voxels and tiles counting as 0.
struct Range {
  float lo = std::numeric_limits<float>::infinity(), hi = 0.0f;
  void add(float v) {
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  void add(const Range& r) {
    lo = std::min(lo, r.lo);
    hi = std::max(hi, r.hi);
  }
  [[nodiscard]] vdb::Vec2s value() const { return {lo, hi}; }
};

// The majorant / minorant trees of a fog grid: one (min, max) voxel per leaf, lower and upper
// internal node, keyed by node origin >> log2(node size). Tiles need none (the walk reads their
// value); a node's range includes its tiles and counts inactive ones as 0.
void buildRanges(VolumeObject::Grid& g) {
  for (auto& r : g.ranges) r = std::make_shared<RangeTree>(vdb::Vec2s(0.0f));
  const TreeT& tree = g.grid->constTree();
  auto key = [](const vdb::Coord& origin, int level) {
    const int s = kLog2Size[level];
    return vdb::Coord(origin.x() >> s, origin.y() >> s, origin.z() >> s);
  };
  for (auto u = tree.root().cbeginChildOn(); u; ++u) {
    Range ru;
    for (auto l = u->cbeginChildOn(); l; ++l) {
      Range rl;
      for (auto leaf = l->cbeginChildOn(); leaf; ++leaf) {
        Range r0;
        for (vdb::Index i = 0; i < LeafT::SIZE; ++i)
          r0.add(leaf->isValueOn(i) ? effectiveDensity(leaf->getValue(i)) : 0.0f);
        g.ranges[0]->setValue(key(leaf->origin(), 0), r0.value());
        rl.add(r0);
      }
      for (auto v = l->cbeginValueOn(); v; ++v) rl.add(effectiveDensity(*v));
      if (l->cbeginValueOff()) rl.add(0.0f);
      g.ranges[1]->setValue(key(l->origin(), 1), rl.value());
      ru.add(rl);
    }
    for (auto v = u->cbeginValueOn(); v; ++v) ru.add(effectiveDensity(*v));
    if (u->cbeginValueOff()) ru.add(0.0f);
    g.ranges[2]->setValue(key(u->origin(), 2), ru.value());
  }
}

// The object over a float grid; `where` names its source in messages ("" for grids made in memory).
std::shared_ptr<const VolumeObject> makeFromGrid(vdb::FloatGrid::ConstPtr grid, VolumeKind kind, std::string name,
                                                 const std::string& where, const VolumeQueryConfig& config) {
  if (!grid) throw InvalidArgument("VolumeObject: null grid");
  const std::string what = describeGrid(where, grid->getName());
  validate(config, what);
  if (!grid->transform().isLinear())
    throw InvalidArgument(what + ": non-linear (" + grid->transform().mapType() +
                          ") transform; only linear (affine) grid transforms are supported");
  if (grid->activeVoxelCount() == 0) throw InvalidArgument(what + ": empty grid (no active voxels)");
  // A damaged file (or a careless caller) can give a linear map with NaN, infinite or zero scale:
  // the volume's bounds would be NaN or empty and it would silently never be hit.
  // (The map's matrix is taken from images of the origin and the unit vectors: getAffineMap()
  // would invert it and throw OpenVDB's own error first.)
  {
    const vdb::math::MapBase& map = *grid->transform().baseMap();
    const vdb::Vec3d o = map.applyMap(vdb::Vec3d(0.0));
    const vdb::Vec3d x = map.applyMap(vdb::Vec3d(1, 0, 0)) - o, y = map.applyMap(vdb::Vec3d(0, 1, 0)) - o,
                     z = map.applyMap(vdb::Vec3d(0, 0, 1)) - o;
    bool finite = true;
    for (const vdb::Vec3d& v : {o, x, y, z})
      finite = finite && std::isfinite(v.x()) && std::isfinite(v.y()) && std::isfinite(v.z());
    const double det = x.dot(y.cross(z));
    if (!finite || !std::isfinite(det) || det == 0.0)
      throw InvalidArgument(
          what + ": grid transform is not finite and invertible (voxel size or matrix is NaN, infinite or zero)");
  }

  auto g = std::make_shared<VolumeObject::Grid>();
  g->grid = grid;
  g->grid_name = grid->getName();
  g->kind = kind != VolumeKind::Auto                      ? kind
            : grid->getGridClass() == vdb::GRID_LEVEL_SET ? VolumeKind::LevelSet
                                                          : VolumeKind::Fog;
  const vdb::CoordBBox bbox = grid->evalActiveVoxelBoundingBox();
  const double margin = g->kind == VolumeKind::LevelSet ? 1.0 : 0.5;
  g->clip_min_is = bbox.min().asVec3d() - vdb::Vec3d(margin);
  g->clip_max_is = bbox.max().asVec3d() + vdb::Vec3d(margin);
  // Object-space bounds: the clip box's corners through the (affine) grid transform.
  Box b;
  for (int c = 0; c < 8; ++c) {
    const vdb::Vec3d p_is((c & 1) ? g->clip_max_is.x() : g->clip_min_is.x(),
                          (c & 2) ? g->clip_max_is.y() : g->clip_min_is.y(),
                          (c & 4) ? g->clip_max_is.z() : g->clip_min_is.z());
    const vdb::Vec3d p_os = grid->transform().indexToWorld(p_is);
    b.extend(glm::vec3(static_cast<float>(p_os.x()), static_cast<float>(p_os.y()), static_cast<float>(p_os.z())));
  }
  if (b.empty() || !b.finite())
    throw InvalidArgument(
        what + ": object-space bounds are not finite (the grid transform takes the active voxels beyond float range)");
  g->bounds_os = b;
  if (g->kind == VolumeKind::Fog) buildRanges(*g);
  if (name.empty()) name = g->grid_name;
  const ObjectRole role = g->kind == VolumeKind::LevelSet ? ObjectRole::Surface : ObjectRole::Medium;
  return std::make_shared<const VolumeObject>(std::move(name), role, std::move(g), config,
                                              VolumeObject::ConstructTag{});
}

}  // namespace

VolumeObject::VolumeObject(std::string name, ObjectRole role, std::shared_ptr<const Grid> grid,
                           const VolumeQueryConfig& config, ConstructTag)
    : Object(std::move(name), role), grid_(std::move(grid)), config_(config) {}

std::shared_ptr<const VolumeObject> VolumeObject::withConfig(const VolumeQueryConfig& config) const {
  validate(config, "volume '" + name() + "'");
  return std::make_shared<const VolumeObject>(name(), role(), grid_, config, ConstructTag{});
}

VolumeObject::~VolumeObject() = default;

Box VolumeObject::bounds() const { return grid_->bounds_os; }

std::uint64_t VolumeObject::contentHash() const {
  // Streamed through a buffer flushed at 1 MiB (each flushed buffer's hash seeds the next one's),
  // reserved with room for the append that crosses that mark (at most a leaf's 2 KiB).
  std::vector<unsigned char> buffer;
  buffer.reserve((std::size_t{1} << 20) + 4096);
  std::uint64_t h = 0;
  const auto add = [&](const void* p, std::size_t n) {
    const auto* c = static_cast<const unsigned char*>(p);
    buffer.insert(buffer.end(), c, c + n);
    if (buffer.size() >= (std::size_t{1} << 20)) {
      h = xxh64(buffer, h);
      buffer.clear();
    }
  };
  using namespace volume_detail;
  const vdb::FloatGrid& grid = *grid_->grid;
  const auto kind = static_cast<std::uint8_t>(grid_->kind);
  add(&kind, 1);
  const vdb::Mat4d m = grid.transform().baseMap()->getAffineMap()->getMat4();
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) {
      const double x = m(r, c);
      add(&x, sizeof x);
    }
  const float background = grid.background();
  add(&background, sizeof background);
  // Every value, active or not: level sets interpolate inactive voxels and read the sign of
  // inactive tiles across gaps. Values above the leaves (tiles) one by one with their place and
  // state; each leaf as its origin, its value mask and its 512 values in one piece.
  const TreeT& tree = grid.constTree();
  auto tiles = tree.cbeginValueAll();
  tiles.setMaxDepth(TreeT::ValueAllCIter::LEAF_DEPTH - 1);
  for (; tiles; ++tiles) {
    const vdb::Coord ijk = tiles.getCoord();
    const std::int32_t record[5] = {ijk.x(), ijk.y(), ijk.z(), static_cast<std::int32_t>(tiles.getDepth()),
                                    tiles.isValueOn() ? 1 : 0};
    const float value = *tiles;
    add(record, sizeof record);
    add(&value, sizeof value);
  }
  for (auto leaf = tree.cbeginLeaf(); leaf; ++leaf) {
    const vdb::Coord o = leaf->origin();
    const std::int32_t origin[3] = {o.x(), o.y(), o.z()};
    add(origin, sizeof origin);
    const auto& mask = leaf->getValueMask();
    for (vdb::Index w = 0; w < mask.WORD_COUNT; ++w) {
      const auto word = mask.template getWord<vdb::Index64>(w);
      add(&word, sizeof word);
    }
    add(leaf->buffer().data(), sizeof(float) * LeafT::SIZE);
  }
  // The query options change the answers too (a new field must be added here: the assert counts
  // them by size).
  const VolumeQueryConfig& q = config_;
  static_assert(sizeof(VolumeQueryConfig) == 48, "VolumeQueryConfig changed: hash its new fields here");
  const auto method = static_cast<std::uint8_t>(q.transmittance);
  const std::uint8_t residual = q.residual ? 1 : 0;
  add(&method, 1);
  add(&q.samples, sizeof q.samples);
  add(&q.march_step, sizeof q.march_step);
  add(&q.majorant_level, sizeof q.majorant_level);
  add(&residual, 1);
  add(&q.seed, sizeof q.seed);
  add(&q.levelset_step, sizeof q.levelset_step);
  add(&q.refine_steps, sizeof q.refine_steps);
  return xxh64(buffer, h);
}

VolumeKind VolumeObject::kind() const { return grid_->kind; }
const std::string& VolumeObject::gridName() const { return grid_->grid_name; }
double VolumeObject::voxelSize() const { return grid_->grid->voxelSize().x(); }
std::uint64_t VolumeObject::activeVoxelCount() const { return grid_->grid->activeVoxelCount(); }

std::vector<ObjectFigure> VolumeObject::figures() const {
  return {{"active_voxels", static_cast<std::size_t>(activeVoxelCount())}};
}
std::size_t VolumeObject::memoryBytes() const {
  std::size_t bytes = sizeof(*this) + sizeof(Grid) + grid_->grid->memUsage() + grid_->surface_bytes.load();
  for (const auto& r : grid_->ranges)
    if (r) bytes += r->memUsage();
  return bytes;
}

float VolumeObject::maxDensity() const {
  float m = 0.0f;
  if (grid_->kind != VolumeKind::Fog) return m;
  // The upper nodes' maxima, and root-level tiles (which have no node).
  for (auto v = grid_->ranges[2]->cbeginValueOn(); v; ++v) m = std::max(m, v->y());
  for (auto t = grid_->grid->constTree().root().cbeginValueOn(); t; ++t) m = std::max(m, effectiveDensity(*t));
  return m;
}

bool VolumeObject::intersect(const Ray& ray_os, Hit& hit, QueryContext& ctx) const {
  if (grid_->kind != VolumeKind::LevelSet) return false;
  RayI ray;
  if (!indexRay(*grid_, ray_os, ray_os.tnear, std::min<double>(ray_os.tfar, hit.t), 0.0, ray)) return false;
  ThreadState& s = threadState(this, grid_, ctx);
  bool found = false;
  forEachCrossing(ray, s, config_, [&](double t) {
    if (static_cast<float>(t) > hit.t) return true;  // rounding at the end of the range
    const std::uint32_t instance = hit.instance_id;
    hit = crossingHit(*grid_, s.acc, ray, t);
    hit.instance_id = instance;
    found = true;
    return true;
  });
  return found;
}

bool VolumeObject::occluded(const Ray& ray_os, QueryContext& ctx) const {
  if (grid_->kind != VolumeKind::LevelSet) return false;
  RayI ray;
  if (!indexRay(*grid_, ray_os, ray_os.tnear, ray_os.tfar, 0.0, ray)) return false;
  bool found = false;
  forEachCrossing(ray, threadState(this, grid_, ctx), config_, [&](double) { return found = true; });
  return found;
}

void VolumeObject::intersectAll(const Ray& ray_os, std::vector<Hit>& hits, QueryContext& ctx) const {
  if (grid_->kind != VolumeKind::LevelSet) return;
  RayI ray;
  if (!indexRay(*grid_, ray_os, ray_os.tnear, ray_os.tfar, 0.0, ray)) return;
  ThreadState& s = threadState(this, grid_, ctx);
  forEachCrossing(ray, s, config_, [&](double t) {
    hits.push_back(crossingHit(*grid_, s.acc, ray, t));
    return false;
  });
}

// ---- Closest points on level sets ----

namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();

// Index-space gradient of the interpolated distance (central differences half a voxel apart), in
// object-space units per index unit.
vdb::Vec3d gradientIS(AccessorT& acc, const vdb::Vec3d& p) {
  const double h = 0.5;
  return vdb::Vec3d(sampleIS(acc, p + vdb::Vec3d(h, 0, 0)) - sampleIS(acc, p - vdb::Vec3d(h, 0, 0)),
                    sampleIS(acc, p + vdb::Vec3d(0, h, 0)) - sampleIS(acc, p - vdb::Vec3d(0, h, 0)),
                    sampleIS(acc, p + vdb::Vec3d(0, 0, h)) - sampleIS(acc, p - vdb::Vec3d(0, 0, h))) /
         (2.0 * h);
}

// Index-space point p moved onto the zero crossing along the gradient (Newton steps). Outside the
// narrow band the distance is constant and p stays where it is.
vdb::Vec3d projectToSurface(AccessorT& acc, vdb::Vec3d p) {
  for (int i = 0; i < 8; ++i) {
    const double phi = sampleIS(acc, p);
    const vdb::Vec3d g = gradientIS(acc, p);
    const double g2 = g.lengthSqr();
    if (!(g2 > 0.0) || !std::isfinite(g2)) break;
    const vdb::Vec3d step = g * (phi / g2);
    p -= step;
    if (step.lengthSqr() < 1e-18) break;
  }
  return p;
}

glm::vec3 toVec3(const vdb::Vec3d& p) {
  return glm::vec3(static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z()));
}

// Every sign change of the grid's values along an edge of the voxel lattice, at the linear zero of
// the edge (which is where the trilinear interpolant vanishes on it): each edge once, from its
// active end with the smaller coordinate, or from its active end when the other is inactive.
std::vector<glm::vec3> latticeCrossings(const VolumeObject::Grid& g) {
  const TreeT& tree = g.grid->constTree();
  const vdb::math::Transform& xform = g.grid->transform();
  vdb::tree::LeafManager<const TreeT> leaves(tree);
  tbb::enumerable_thread_specific<std::vector<glm::vec3>> found;
  // Isolated: the first query often runs inside a parallel batch of queries, and a thread waiting
  // for this loop must not pick up another query of the batch, which would enter the same
  // call_once again.
  tbb::this_task_arena::isolate([&] {
    tbb::parallel_for(leaves.leafRange(), [&](const vdb::tree::LeafManager<const TreeT>::LeafRange& range) {
      AccessorT acc(tree);
      std::vector<glm::vec3>& out = found.local();
      for (auto leaf = range.begin(); leaf; ++leaf)
        for (auto v = leaf->cbeginValueOn(); v; ++v) {
          const vdb::Coord c = v.getCoord();
          const float a = *v;
          if (a == 0.0f) {
            out.push_back(toVec3(xform.indexToWorld(c.asVec3d())));
            continue;
          }
          for (int axis = 0; axis < 3; ++axis)
            for (const int dir : {1, -1}) {
              vdb::Coord n = c;
              n[axis] += dir;
              if (dir < 0 && acc.isValueOn(n)) continue;  // that voxel reports the edge
              const float b = acc.getValue(n);
              if (b == 0.0f || (a < 0.0f) == (b < 0.0f)) continue;
              vdb::Vec3d p = c.asVec3d();
              p[axis] += dir * static_cast<double>(a) / (static_cast<double>(a) - b);
              out.push_back(toVec3(xform.indexToWorld(p)));
            }
        }
    });
  });
  std::vector<glm::vec3> all;
  for (const std::vector<glm::vec3>& part : found) all.insert(all.end(), part.begin(), part.end());
  // The same points in the same order whatever the threads did (the BVH and ties depend on it).
  std::sort(all.begin(), all.end(), [](const glm::vec3& x, const glm::vec3& y) {
    return x.x != y.x ? x.x < y.x : (x.y != y.y ? x.y < y.y : x.z < y.z);
  });
  all.erase(std::unique(all.begin(), all.end()), all.end());
  return all;
}

// A BVH over the points, median splits on the longest axis, leaves of up to 8 points.
std::uint32_t buildPointNodes(SurfacePoints& sp, std::uint32_t begin, std::uint32_t end) {
  const auto index = static_cast<std::uint32_t>(sp.nodes.size());
  sp.nodes.emplace_back();
  Box box;
  for (std::uint32_t i = begin; i < end; ++i) box.extend(sp.points_os[i]);
  if (end - begin <= 8) {
    sp.nodes[index] = {box, begin, end - begin};
    return index;
  }
  const int axis = box.longestAxis();
  const std::uint32_t mid = begin + (end - begin) / 2;
  std::nth_element(sp.points_os.begin() + begin, sp.points_os.begin() + mid, sp.points_os.begin() + end,
                   [axis](const glm::vec3& x, const glm::vec3& y) { return x[axis] < y[axis]; });
  (void)buildPointNodes(sp, begin, mid);
  const std::uint32_t right = buildPointNodes(sp, mid, end);
  sp.nodes[index] = {box, right, 0};
  return index;
}

const SurfacePoints& surfacePoints(const VolumeObject::Grid& g) {
  std::call_once(g.surface_once, [&g] {
    auto sp = std::make_shared<SurfacePoints>();
    sp->points_os = latticeCrossings(g);
    if (!sp->points_os.empty()) (void)buildPointNodes(*sp, 0, static_cast<std::uint32_t>(sp->points_os.size()));
    g.surface_bytes = sp->memoryBytes();
    g.surface = std::move(sp);
  });
  return *g.surface;
}

}  // namespace

bool VolumeObject::closestPoint(const PointQuery& q, ClosestPoint& best, QueryContext& ctx) const {
  if (grid_->kind != VolumeKind::LevelSet) return false;
  const SurfacePoints& sp = surfacePoints(*grid_);
  if (sp.nodes.empty()) return false;
  const vdb::math::MapBase& map = *grid_->grid->transform().baseMap();
  const Affine& world_from_object = q.world_from_object;
  const Affine object_from_world = world_from_object.inverse();
  const auto toWorld = [&](const vdb::Vec3d& p_is) {
    const vdb::Vec3d o = map.applyMap(p_is);
    return world_from_object.point(glm::dvec3(o.x(), o.y(), o.z()));
  };
  const auto toIndex = [&](const glm::dvec3& p_ws) {
    const glm::dvec3 o = object_from_world.point(p_ws);
    return map.applyInverseMap(vdb::Vec3d(o.x, o.y, o.z));
  };
  // A bound of a voxel cell's world diagonal: the surface inside a cell crosses one of its edges
  // (trilinear weights are positive), so a lattice crossing lies within it of any surface point.
  double cell = 0.0;
  for (int a = 0; a < 3; ++a) {
    vdb::Vec3d e(0.0);
    e[a] = 1.0;
    const vdb::Vec3d j = map.applyJacobian(e);
    cell += glm::length(world_from_object.vector(glm::dvec3(j.x(), j.y(), j.z())));
  }
  // Calls visit(i, world distance) for every lattice crossing nearer than `limit` (which visit may
  // lower), nearer subtrees first.
  const auto forEachWithin = [&](double limit, auto&& visit) {
    std::uint32_t stack[64];
    std::size_t size = 0;
    stack[size++] = 0;
    while (size > 0) {
      const SurfacePoints::Node& node = sp.nodes[stack[--size]];
      if (!q.mayReach(node.box, limit)) continue;
      if (node.count > 0) {
        for (std::uint32_t i = node.first; i < node.first + node.count; ++i) {
          const double d = glm::length(world_from_object.point(glm::dvec3(sp.points_os[i])) - q.point_ws);
          if (d < limit) limit = visit(i, d, limit);
        }
        continue;
      }
      const std::uint32_t left = static_cast<std::uint32_t>(&node - sp.nodes.data()) + 1, right = node.first;
      const bool left_first =
          distanceSquared(sp.nodes[left].box, q.point_os) <= distanceSquared(sp.nodes[right].box, q.point_os);
      stack[size++] = left_first ? right : left;
      stack[size++] = left_first ? left : right;
    }
  };
  // The nearest lattice crossing, searched a cell beyond the best distance so far (the surface
  // point the refinement reaches may be that much closer than the crossing it starts from).
  std::uint32_t nearest = kInvalidId;
  double nearest_d = kInfinity;
  forEachWithin(best.distance + cell, [&](std::uint32_t i, double d, double) {
    nearest = i;
    nearest_d = d;
    return d;
  });
  if (nearest == kInvalidId) return false;
  // The true foot may lie on another part of the surface (a wall across a thin gap, the other
  // side of a saddle) whose crossings are up to a cell farther than the nearest: every crossing
  // within a cell of the nearest seeds a refinement, one per cluster (seeds two cells apart), the
  // nearest first.
  std::vector<std::pair<double, std::uint32_t>> within;
  forEachWithin(std::min(nearest_d + cell, best.distance + cell), [&](std::uint32_t i, double d, double limit) {
    within.emplace_back(d, i);
    return limit;
  });
  std::sort(within.begin(), within.end());
  constexpr std::size_t kMaxSeeds = 8;
  std::vector<std::uint32_t> seeds;
  std::vector<glm::dvec3> seeds_ws;
  for (const auto& [d, i] : within) {
    const glm::dvec3 p = world_from_object.point(glm::dvec3(sp.points_os[i]));
    bool clustered = false;
    for (const glm::dvec3& s : seeds_ws) clustered = clustered || glm::length(p - s) < 2.0 * cell;
    if (clustered) continue;
    seeds.push_back(i);
    seeds_ws.push_back(p);
    if (seeds.size() == kMaxSeeds) break;
  }

  // Refine on the surface: minimise the world distance over the surface near the crossing, in
  // coordinates (a, b) of the tangent plane (world space, so that any affine transform gets its
  // world-nearest point), each trial point projected onto the zero crossing (Newton in index space).
  // A quadratic model from five trial points gives a Newton step; the trial spacing shrinks with the
  // steps. Derivative-free on purpose: the interpolant's gradient is a few degrees off, which from
  // far away would move the foot by a good part of a voxel.
  AccessorT& acc = threadState(this, grid_, ctx).acc;
  const auto worldNormal = [&](const vdb::Vec3d& p_is) {
    const vdb::Vec3d n_os = map.applyIJT(gradientIS(acc, p_is));
    const glm::dvec3 n = glm::transpose(object_from_world.linear) * glm::dvec3(n_os.x(), n_os.y(), n_os.z());
    const double len = glm::length(n);
    return len > 0.0 && std::isfinite(len) ? n / len : glm::dvec3(0.0);
  };
  struct SurfacePoint {
    vdb::Vec3d p_is;
    glm::dvec3 p_ws;
    double d = kInfinity;
  };
  // Outside the narrow band the projection cannot reach the surface: such trial points count as
  // infinitely far.
  const double on_surface = 1e-4 * voxelSize();
  const auto project = [&](const vdb::Vec3d& p_is) {
    SurfacePoint out;
    out.p_is = projectToSurface(acc, p_is);
    if (std::abs(sampleIS(acc, out.p_is)) <= on_surface) {
      out.p_ws = toWorld(out.p_is);
      out.d = glm::length(out.p_ws - q.point_ws);
    }
    return out;
  };
  const auto refine = [&](std::uint32_t seed) {
    const glm::vec3& start = sp.points_os[seed];
    SurfacePoint x = project(map.applyInverseMap(vdb::Vec3d(start.x, start.y, start.z)));
    if (!(x.d < kInfinity)) {  // the crossing itself, unrefined, when Newton cannot settle there
      x.p_is = map.applyInverseMap(vdb::Vec3d(start.x, start.y, start.z));
      x.p_ws = toWorld(x.p_is);
      x.d = glm::length(x.p_ws - q.point_ws);
    }
    double h = 0.25 * cell;
    const double h_min = 1e-9 * cell;
    for (int iteration = 0; iteration < 40 && h > h_min && x.d > 0.0; ++iteration) {
      const glm::dvec3 n = worldNormal(x.p_is);
      if (n == glm::dvec3(0.0)) break;
      const glm::dvec3 t1 =
          glm::normalize(std::abs(n.x) < 0.6 ? glm::cross(n, glm::dvec3(1, 0, 0)) : glm::cross(n, glm::dvec3(0, 1, 0)));
      const glm::dvec3 t2 = glm::cross(n, t1);
      const auto trial = [&](double a, double b) { return project(toIndex(x.p_ws + a * t1 + b * t2)); };
      const SurfacePoint ap = trial(h, 0), am = trial(-h, 0), bp = trial(0, h), bm = trial(0, -h), ab = trial(h, h);
      SurfacePoint next = x;
      for (const SurfacePoint* c : {&ap, &am, &bp, &bm, &ab})
        if (c->d < next.d) next = *c;
      if (ap.d < kInfinity && am.d < kInfinity && bp.d < kInfinity && bm.d < kInfinity && ab.d < kInfinity) {
        const double ga = (ap.d - am.d) / (2 * h), gb = (bp.d - bm.d) / (2 * h);
        const double haa = (ap.d - 2 * x.d + am.d) / (h * h), hbb = (bp.d - 2 * x.d + bm.d) / (h * h);
        const double hab = (ab.d - ap.d - bp.d + x.d) / (h * h);
        const double det = haa * hbb - hab * hab;
        double da, db;
        if (haa > 0 && det > 0) {  // the model has a minimum: its Newton step
          da = -(hbb * ga - hab * gb) / det;
          db = -(haa * gb - hab * ga) / det;
        } else {  // downhill by the spacing
          const double g = std::hypot(ga, gb);
          da = g > 0 ? -h * ga / g : 0.0;
          db = g > 0 ? -h * gb / g : 0.0;
        }
        const double len = std::hypot(da, db);
        if (len > 4 * h) {
          da *= 4 * h / len;
          db *= 4 * h / len;
        }
        const SurfacePoint newton = trial(da, db);
        if (newton.d < next.d) next = newton;
        if (next.d < x.d) h = std::clamp(std::hypot(da, db), 0.05 * h, 2 * h);
      }
      if (!(next.d < x.d)) {
        h *= 0.25;  // nothing closer at this spacing: look nearer
        continue;
      }
      x = next;
    }
    return x;
  };
  // A foot nearer than the best so far has a crossing within a cell of it, whose cluster's seed is
  // no farther: seeds beyond best + cell cannot lead there.
  SurfacePoint x;
  for (std::size_t k = 0; k < seeds.size(); ++k) {
    if (!(glm::length(seeds_ws[k] - q.point_ws) < x.d + cell)) continue;
    const SurfacePoint y = refine(seeds[k]);
    if (y.d < x.d) x = y;
  }
  const glm::dvec3 n_ws = worldNormal(x.p_is);
  const glm::dvec3 x_ws = x.p_ws;
  const double d = x.d;
  if (!(d < best.distance)) return false;
  best.distance = d;
  best.point_ws = x_ws;
  best.normal_ws = n_ws;
  best.prim_id = 0;
  return true;
}

std::shared_ptr<const VolumeObject> makeVolumeObject(vdb::FloatGrid::ConstPtr grid, VolumeKind kind, std::string name,
                                                     const VolumeQueryConfig& config) {
  initializeOpenVdb();
  return makeFromGrid(std::move(grid), kind, std::move(name), "", config);
}

std::shared_ptr<const VolumeObject> VolumeObject::load(const std::filesystem::path& file,
                                                       const VolumeLoadOptions& options) {
  const std::string f = file.string();
  if (const std::string problem = notRegularFile(file); !problem.empty()) throw FileError(f + ": " + problem);
  initializeOpenVdb();
  // Our own walk of the file's layout first: OpenVDB must never see a grid that runs past the end.
  (void)checkVdbFileStructure(file);
  vdb::FloatGrid::Ptr grid;
  try {
    vdb::io::File in(f);
    in.open(/*delayLoad=*/false);  // read everything now: a truncated file must fail here
    std::string chosen;
    std::ostringstream listing;                                 // "name (type), ..." for messages
    const vdb::GridPtrVecPtr metas = in.readAllGridMetadata();  // OpenVDB lists grids by name
    for (const vdb::GridBase::Ptr& meta : *metas) {
      const std::string gname = meta->getName();
      listing << (listing.tellp() > 0 ? ", " : "") << '"' << gname << "\" (" << meta->valueType() << ")";
      const bool is_float = meta->isType<vdb::FloatGrid>();
      if (!options.grid.empty() && gname == options.grid) {
        if (!is_float)
          throw FileError(f + ": grid \"" + options.grid + "\" holds " + meta->valueType() + " values, not float");
        chosen = gname;
      } else if (options.grid.empty() && is_float && chosen.empty()) {
        chosen = gname;
      }
    }
    const std::string grids = listing.tellp() > 0 ? listing.str() : "none";
    if (chosen.empty() && !options.grid.empty())
      throw FileError(f + ": no grid named \"" + options.grid + "\" (grids: " + grids + ")");
    if (chosen.empty()) throw FileError(f + ": no float grid (grids: " + grids + ")");
    grid = vdb::gridPtrCast<vdb::FloatGrid>(in.readGrid(chosen));
    in.close();
    if (!grid) throw FileError(f + ": grid \"" + chosen + "\" could not be read as a float grid");
  } catch (const Error&) {
    throw;
  } catch (const std::exception& e) {
    throw FileError(f + ": not a readable .vdb file (truncated or malformed?): " + e.what());
  }
  std::string name = options.name.empty() ? file.stem().string() + ":" + grid->getName() : options.name;
  return makeFromGrid(std::move(grid), options.kind, std::move(name), f, options.query);
}

}  // namespace duplex
