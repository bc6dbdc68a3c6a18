#pragma once
// Private to accel/src: a uniform grid over the sensors' level, the crossing query's walk when the
// level holds many sensors (TopLevel::intersectWithCrossings; TopLevelConfig::crossing_grid).
//
// Why a grid beside the kd-tree: the sensors' walk asks for every sensor box a segment meets up
// to a known t (no closest hit, no early exit), and benchmark-like scenes spread thousands of small
// sensors through a room. A 3D-DDA (Amanatides and Woo 1987, written as a merge of the three
// axes' plane crossings, without a branch per cell) lists the cells a segment passes, and one
// vector test (LeafBoxes) covers their boxes, where the
// kd-tree's walk pays unpredictable node steps and tests whole leaves. The grid is rebuilt from the
// boxes after every commit of the level, in O(sensors + references) like the leaf-ordered boxes.
//
// Exactness: a cell lists every box that comes within `margin` of it (boxes are widened by the
// margin when they are inserted), and the walk is used only for rays whose rounding (of the entry
// point and of the cell crossings, a few float epsilons of the coordinates' magnitude) stays well
// below that margin; other rays, and levels where a grid would be poor (few sensors, or sensors
// spanning many cells), take the kd-tree. Either way the boxes met are a superset of the sensors
// crossed, and the crossings themselves come from the same exact test.
//
// Flat sensors (a world rectangle, FlatQuad) are listed only in the cells their rectangle, not
// just their box, comes within `margin` of, and an entry's box is the box of the part of the
// rectangle within `margin` of its cell (widened by the margin, within the sensor's own box): a
// tilted sensor that straddles a cell plane is then met in the cell where the ray passes it, not
// in every cell its box reaches. Exact for the same reason as above: a crossing lies on the
// rectangle (up to the object-space ray's rounding, far below the margin) and in or within the
// walk's rounding of a cell the walk visits, so within `margin` of that cell, and so inside that
// cell's entry box.

#include "duplex/accel/Box.h"
#include "duplex/accel/KdTraversal.h"
#include "duplex/accel/Ray.h"
#include "duplex/accel/FloatRounding.h"
#include "LeafBoxes.h"

#include <glm/vec3.hpp>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

namespace duplex::toplevel_detail {

// A flat instance's rectangle in world space: its corners in order around it (double: the clip
// against cells must not lose what the margin keeps).
struct FlatQuad {
  std::array<glm::dvec3, 4> corner;
};

struct CrossingGrid {
  // Below this many live boxes the kd-tree is as fast and the grid is not built.
  static constexpr std::size_t kMinBoxes = 256;
  // Cells per box (cubic cells over the boxes' bounds): a cell holds about eight boxes (a dozen
  // entries with the boxes that reach in from its neighbours), one or two vector tests. Finer
  // grids take more cell steps than they save box tests, coarser ones more box tests than they
  // save cell steps (docs/design/sensors.md, "Speed").
  static constexpr double kCellsPerBox = 0.125;
  // The grid is dropped when boxes span more cells than this on average (large sensors).
  static constexpr double kMaxRefsPerBox = 4.0;
  static constexpr std::uint32_t kMaxDim = 512;

  LeafBoxes boxes;                        // entry boxes in cell order (vector tests)
  std::vector<std::uint32_t> slots;       // slot of each entry, cell order
  std::vector<std::uint32_t> cell_begin;  // entries of cell c: [cell_begin[c], cell_begin[c + 1])
  std::uint32_t dims[3] = {1, 1, 1};
  float lo[3] = {0, 0, 0};
  float cell[3] = {0, 0, 0};      // cell size per axis (0 on an axis of zero extent)
  float inv_cell[3] = {0, 0, 0};  // 1 / cell (0 on such an axis: everything in cell 0)
  float margin = 0.0f;            // world units a box is widened by when inserted
  float magnitude = 0.0f;         // largest |coordinate| of the grid's bounds
  Box bounds;                     // the boxes' bounds widened by the margin

  [[nodiscard]] bool usable() const { return !cell_begin.empty(); }

  // Rebuilds over the non-empty boxes of `by_slot` (free slots hold empty boxes), or leaves the
  // grid unusable when it would not pay. The flat instances' rectangles narrow their entries (see
  // the top of this file): quad_of(slot, quad) fills in the rectangle of a flat slot and returns
  // true (false: use its box). Asked only for boxes that reach into more than one cell (a box within one cell has
  // one entry, its own box), so that a commit of the level (which refreshes the grid) stays O(n)
  // with a small constant.
  template <class QuadOf>
  void refresh(const std::vector<Box>& by_slot, QuadOf&& quad_of) {
    cell_begin.clear();
    slots.clear();
    std::size_t n = 0;
    Box all;
    for (const Box& b : by_slot) {
      if (b.empty()) continue;
      ++n;
      all.extend(b);
    }
    if (n < kMinBoxes) return;
    const glm::vec3 ext = all.hi - all.lo;
    magnitude = std::max({std::abs(all.lo.x), std::abs(all.lo.y), std::abs(all.lo.z), std::abs(all.hi.x),
                          std::abs(all.hi.y), std::abs(all.hi.z)});
    if (!std::isfinite(magnitude)) return;
    // Cubic cells over the axes thicker than a cell; a thinner axis gets one cell and leaves the
    // volume the cells share (else a thin, nearly flat layout, e.g. sensors on a slightly tilted
    // floor, divides a tiny volume into cells far smaller than the layout's width: up to kMaxDim^2
    // cells for a few boxes).
    bool thin[3] = {!(ext[0] > 0.0f), !(ext[1] > 0.0f), !(ext[2] > 0.0f)};
    double side = 1.0;
    for (int pass = 0; pass < 3; ++pass) {
      double volume = 1.0;
      int axes = 0;
      for (int k = 0; k < 3; ++k)
        if (!thin[k]) {
          volume *= ext[k];
          ++axes;
        }
      side = axes == 0 ? 1.0 : std::pow(volume / (kCellsPerBox * static_cast<double>(n)), 1.0 / axes);
      bool changed = false;
      for (int k = 0; k < 3; ++k)
        if (!thin[k] && ext[k] < side) thin[k] = changed = true;
      if (!changed) break;
    }
    std::uint64_t cells = 1;
    for (int k = 0; k < 3; ++k) {
      dims[k] = thin[k] ? 1u : static_cast<std::uint32_t>(std::clamp(std::ceil(ext[k] / side), 1.0, double(kMaxDim)));
      cells *= dims[k];
      lo[k] = all.lo[k];
      cell[k] = ext[k] > 0.0f ? ext[k] / static_cast<float>(dims[k]) : 0.0f;
      inv_cell[k] = ext[k] > 0.0f ? static_cast<float>(dims[k]) / ext[k] : 0.0f;
    }
    constexpr float eps = std::numeric_limits<float>::epsilon();
    margin = 1e-3f * std::max({cell[0], cell[1], cell[2]}) + 128.0f * eps * magnitude;
    bounds = Box(all.lo - glm::vec3(margin), all.hi + glm::vec3(margin));
    // The cells within `margin` of each box; the grid is dropped when they are too many.
    auto range = [&](const Box& b, std::uint32_t a[3], std::uint32_t z[3]) {
      for (int k = 0; k < 3; ++k) {
        a[k] = cellOf(k, b.lo[k] - margin);
        z[k] = cellOf(k, b.hi[k] + margin);
      }
    };
    std::uint64_t refs = 0;
    for (const Box& b : by_slot) {
      if (b.empty()) continue;
      std::uint32_t a[3], z[3];
      range(b, a, z);
      refs += std::uint64_t{z[0] - a[0] + 1} * (z[1] - a[1] + 1) * (z[2] - a[2] + 1);
      if (static_cast<double>(refs) > kMaxRefsPerBox * static_cast<double>(n)) return;
    }
    // The entries (slot order within a cell), with their boxes: a flat instance only where its
    // rectangle comes within `margin` of the cell, with the box of that part.
    std::vector<Entry>& entries = scratch_entries_;
    entries.clear();
    entries.reserve(refs);
    std::vector<std::uint32_t> count(cells + 1, 0);
    for (std::uint32_t slot = 0; slot < by_slot.size(); ++slot) {
      const Box& b = by_slot[slot];
      if (b.empty()) continue;
      std::uint32_t a[3], z[3];
      range(b, a, z);
      FlatQuad quad;
      const bool flat = (a[0] != z[0] || a[1] != z[1] || a[2] != z[2]) && quad_of(slot, quad);
      for (std::uint32_t iz = a[2]; iz <= z[2]; ++iz)
        for (std::uint32_t iy = a[1]; iy <= z[1]; ++iy)
          for (std::uint32_t ix = a[0]; ix <= z[0]; ++ix) {
            Box entry_box = b;
            if (flat) {
              const std::uint32_t at[3] = {ix, iy, iz};
              if (!quadNearCell(quad, b, at, entry_box)) continue;
              entry_box = intersection(entry_box, b);
            }
            const std::uint32_t c = index(ix, iy, iz);
            entries.push_back({c, slot, entry_box});
            ++count[c + 1];
          }
    }
    for (std::size_t c = 1; c <= cells; ++c) count[c] += count[c - 1];
    slots.resize(entries.size());
    std::vector<Box>& entry_boxes = scratch_boxes_;
    entry_boxes.resize(entries.size());
    std::vector<std::uint32_t> fill(count.begin(), count.end() - 1);
    for (const Entry& e : entries) {
      const std::uint32_t at = fill[e.cell]++;
      slots[at] = e.slot;
      entry_boxes[at] = e.box;
    }
    boxes.refresh(entry_boxes);
    cell_begin = std::move(count);
  }

  // Calls hit(entry) for the entries (boxes of the cells the ray passes within [ray.tnear, t_max])
  // whose box it meets within [ray.tnear, t_max]; slots[entry] is the box's slot (a box spanning
  // several cells comes once per cell), in no particular order. `dir` is the ray's direction; `runs` and `met` are
  // scratch lists. Returns false, having called nothing, when the ray's rounding could exceed the margin, or the ray
  // has a zero direction component (the caller walks the kd-tree instead). `records` (optional): a 64-byte record per
  // entry that hit() reads (LeafBoxes::metInRuns prefetches it). `before(met, n)` (optional) sees the n entries met
  // before hit() is called for any of them (the crossing query prefetches what the hits will read).
  template <class F, class B = void (*)(const std::uint32_t*, std::uint32_t)>
  bool forEachMet(
      const KdRay& ray, const glm::vec3& dir, float t_max, std::vector<std::uint32_t>& runs,
      std::vector<std::uint32_t>& met, F&& hit, const void* records = nullptr,
      B&& before = [](const std::uint32_t*, std::uint32_t) {}) const {
#if !defined(DUPLEX_LEAF_BOXES_X86)
    (void)ray, (void)dir, (void)t_max, (void)runs, (void)met, (void)hit, (void)records, (void)before;
    return false;  // no vector box test (LeafBoxes.h): the kd-tree
#else
    if (boxes.lanes == 1 || ray.zero[0] || ray.zero[1] || ray.zero[2]) return false;
    float t0 = ray.tnear, t1 = t_max;
    if (!clipIntervalToBox(ray, bounds, t0, t1)) return true;  // misses every box
    const float reach =
        std::max({std::abs(ray.origin[0]), std::abs(ray.origin[1]), std::abs(ray.origin[2]), magnitude}) +
        std::max(std::abs(t0), std::abs(t1)) * std::max({std::abs(dir.x), std::abs(dir.y), std::abs(dir.z)});
    // Entry point and plane crossings are each a few roundings of values up to `reach`.
    if (!(64.0f * std::numeric_limits<float>::epsilon() * reach <= margin)) return false;
    // Per axis: the cell where the ray enters, and the t of every cell plane it crosses up to t1
    // before the grid's boundary (the planes are lo + p * cell).
    // Each axis's t grow with p (every operation is monotonic), so the cells in order along the ray
    // are a merge of the three lists: the walk of Amanatides and Woo without its branch per cell
    // (which plane comes next is a coin flip for random rays: a mispredicted branch per cell cost
    // more than the cell's box tests). Equal t step both axes at once, past the cell touched only
    // at that edge, whose boxes near the ray are within the margin of the cells visited.
    std::int32_t c[3], stride[3];
    std::uint32_t count[3];
    // The plane crossings' t as integer keys that order like the floats (orderKey): the merge's
    // chain from one cell to the next is a load, three compares and an add, and integer loads and
    // compares are shorter than float ones (on AMD Zen 5 a float load takes about twice as long).
    std::int32_t plane_t[3][kMaxDim + 8];
    const std::int32_t axis_stride[3] = {1, static_cast<std::int32_t>(dims[0]),
                                         static_cast<std::int32_t>(dims[0] * dims[1])};
    // No branch on the direction's sign or the entry cell either (each is a coin flip for random
    // rays).
    const float d[3] = {dir.x, dir.y, dir.z};
    for (int k = 0; k < 3; ++k) {
      c[k] = static_cast<std::int32_t>(cellOf(k, ray.origin[k] + t0 * d[k]));
      const auto up = static_cast<std::uint32_t>(d[k] > 0.0f);
      const auto ck = static_cast<std::uint32_t>(c[k]);
      const std::uint32_t left = ck + up * (dims[k] - 1u - 2u * ck);  // dims - 1 - c going up, else c
      const std::int32_t step = 2 * static_cast<std::int32_t>(up) - 1;
      stride[k] = step * axis_stride[k];
      // Eight planes at a time (a loop over single planes mispredicts its exit twice per axis):
      // those with t <= t1 are a prefix (t grows with the plane), and at most `left` count.
      const __m128 lo4 = _mm_set1_ps(lo[k]), cell4 = _mm_set1_ps(cell[k]), o4 = _mm_set1_ps(ray.origin[k]);
      const __m128 inv4 = _mm_set1_ps(ray.inv_dir[k]), end4 = _mm_set1_ps(t1);
      const std::int32_t first = c[k] + static_cast<std::int32_t>(up);
      __m128i plane = _mm_setr_epi32(first, first + step, first + 2 * step, first + 3 * step);
      const __m128i step4 = _mm_set1_epi32(4 * step);
      std::uint32_t n = 0;
      while (true) {
        const __m128 ta = _mm_mul_ps(_mm_sub_ps(_mm_add_ps(lo4, _mm_mul_ps(_mm_cvtepi32_ps(plane), cell4)), o4), inv4);
        plane = _mm_add_epi32(plane, step4);
        const __m128 tb = _mm_mul_ps(_mm_sub_ps(_mm_add_ps(lo4, _mm_mul_ps(_mm_cvtepi32_ps(plane), cell4)), o4), inv4);
        plane = _mm_add_epi32(plane, step4);
        _mm_storeu_si128(reinterpret_cast<__m128i*>(plane_t[k] + n), orderKey(ta));
        _mm_storeu_si128(reinterpret_cast<__m128i*>(plane_t[k] + n + 4), orderKey(tb));
        const auto before_end = static_cast<std::uint32_t>(_mm_movemask_ps(_mm_cmple_ps(ta, end4)) |
                                                           (_mm_movemask_ps(_mm_cmple_ps(tb, end4)) << 4));
        // A prefix: its length is the count of trailing ones (std::popcount would be a library
        // call without -mpopcnt).
        const std::uint32_t got =
            std::min<std::uint32_t>(static_cast<std::uint32_t>(std::countr_one(before_end)), left - n);
        n += got;
        if (got < 8) break;
      }
      plane_t[k][n] = kInfinityKey;
      count[k] = n;
    }
    // The cells first (their runs of entries), then one vector test over all of them.
    const std::uint32_t steps = count[0] + count[1] + count[2];
    if (runs.size() < 2 * (steps + 1)) runs.resize(2 * (steps + 1));
    std::uint32_t* run = runs.data();
    std::uint32_t run_count = 0, entries = 0;
    std::int32_t cell_index = static_cast<std::int32_t>(index(c[0], c[1], c[2]));
    std::uint32_t i0 = 0, i1 = 0, i2 = 0;
    for (std::uint32_t s = 0;; ++s) {
      const std::uint32_t b = cell_begin[static_cast<std::uint32_t>(cell_index)];
      const std::uint32_t e = cell_begin[static_cast<std::uint32_t>(cell_index) + 1];
      run[2 * run_count] = b;
      run[2 * run_count + 1] = e;
      run_count += e > b ? 1u : 0u;
      entries += e - b;
      if (s == steps) break;
      const std::int32_t tx = plane_t[0][i0], ty = plane_t[1][i1], tz = plane_t[2][i2];
      // Bitwise, not &&: each compare is a value, not a branch.
      const bool sx = (tx <= ty) & (tx <= tz), sy = (ty <= tx) & (ty <= tz), sz = (tz <= tx) & (tz <= ty);
      i0 += sx;
      i1 += sy;
      i2 += sz;
      s += static_cast<std::uint32_t>(sx) + sy + sz - 1u;  // ties take several planes in one step
      cell_index += (sx ? stride[0] : 0) + (sy ? stride[1] : 0) + (sz ? stride[2] : 0);
    }
    if (met.size() < entries + LeafBoxes::kMaxLanes) met.resize(entries + LeafBoxes::kMaxLanes);
    const std::uint32_t n = boxes.metInRuns(ray, t_max, run, run_count, met.data(), records);
    before(met.data(), n);
    for (std::uint32_t k = 0; k < n; ++k) hit(met[k]);
    return true;
#endif
  }

 private:
  struct Entry {
    std::uint32_t cell, slot;
    Box box;
  };
  // Scratch lists of refresh(), kept between commits: fresh ones of this size (hundreds of KB)
  // come from new pages, whose faults cost more than the refresh itself.
  std::vector<Entry> scratch_entries_;
  std::vector<Box> scratch_boxes_;

  // Whether the rectangle comes within `margin` of cell `at` (the cell's box widened by the margin;
  // open outwards at the grid's boundary, where the walk clamps); if so, `box` is the box of that
  // part of the rectangle widened by the margin, rounded outwards to float. Sutherland-Hodgman in
  // double: its rounding (about 1e-16 of the coordinates) is far below the margin. Planes that do
  // not cut the rectangle's box `rect_box` are skipped (clipping less keeps more: never too little).
  [[nodiscard]] bool quadNearCell(const FlatQuad& quad, const Box& rect_box, const std::uint32_t at[3],
                                  Box& box) const {
    constexpr std::size_t kMaxVertices = 4 + 6;  // each plane adds at most one vertex
    std::array<glm::dvec3, kMaxVertices> buffers[2];
    glm::dvec3* poly = buffers[0].data();
    glm::dvec3* next = buffers[1].data();
    std::size_t size = 4;
    std::copy(quad.corner.begin(), quad.corner.end(), poly);
    for (int k = 0; k < 3; ++k) {
      const double cell_lo = static_cast<double>(lo[k]) + static_cast<double>(at[k]) * static_cast<double>(cell[k]);
      const double bound[2] = {cell_lo - margin, cell_lo + static_cast<double>(cell[k]) + margin};
      for (int side = 0; side < 2; ++side) {
        if (side == 0 ? at[k] == 0 : at[k] + 1 == dims[k]) continue;  // open outwards
        if (side == 0 ? rect_box.lo[k] >= bound[0] : rect_box.hi[k] <= bound[1]) continue;
        // Inside: p[k] >= bound (lower side) or p[k] <= bound (upper side).
        auto inside = [&](const glm::dvec3& p) { return side == 0 ? p[k] >= bound[0] : p[k] <= bound[1]; };
        std::size_t out = 0;
        for (std::size_t i = 0; i < size; ++i) {
          const glm::dvec3& p = poly[i];
          const glm::dvec3& q = poly[(i + 1) % size];
          const bool p_in = inside(p), q_in = inside(q);
          if (p_in) next[out++] = p;
          if (p_in != q_in) {
            const double s = (bound[side] - p[k]) / (q[k] - p[k]);
            glm::dvec3 x = p + s * (q - p);
            x[k] = bound[side];
            next[out++] = x;
          }
        }
        size = out;
        if (size == 0) return false;
        std::swap(poly, next);
      }
    }
    glm::dvec3 a = poly[0], b = poly[0];
    for (std::size_t i = 1; i < size; ++i) {
      a = glm::min(a, poly[i]);
      b = glm::max(b, poly[i]);
    }
    for (int k = 0; k < 3; ++k) {
      box.lo[k] = detail::floatBelow(a[k] - margin);
      box.hi[k] = detail::floatAbove(b[k] + margin);
    }
    return true;
  }

  // The cell of coordinate x on axis k, clamped to the grid (NaN to cell 0): floor((x - lo) / cell)
  // clamped to [0, dims - 1], computed as a clamp and a truncation (maxss, minss, cvttss2si: the
  // same cell, with no branch; std::floor without SSE4.1 and the test for cells below 0 each had one,
  // and the plain ?: forms compile to branches too).
  [[nodiscard]] std::uint32_t cellOf(int k, float x) const {
#if defined(DUPLEX_LEAF_BOXES_X86)
    const __m128 f = _mm_max_ss(_mm_set_ss((x - lo[k]) * inv_cell[k]), _mm_setzero_ps());  // NaN to 0
    const __m128 clamped = _mm_min_ss(f, _mm_set_ss(static_cast<float>(dims[k] - 1)));
    return static_cast<std::uint32_t>(_mm_cvttss_si32(clamped));  // >= 0: truncation is floor
#else
    const float f = std::floor((x - lo[k]) * inv_cell[k]);
    if (!(f > 0.0f)) return 0;
    return static_cast<std::uint32_t>(std::min(f, static_cast<float>(dims[k] - 1)));
#endif
  }
#if defined(DUPLEX_LEAF_BOXES_X86)
  // Integer keys of floats that compare (as signed 32-bit integers) like the floats: the bits of
  // a non-negative float, the bits with the 31 low ones flipped for a negative one. The one
  // difference: -0 orders before +0, which the float compare calls equal; such a tie then steps
  // the two axes one after the other, visiting also the cell touched only at that edge (more
  // cells, never fewer: the same crossings). No NaN reaches the walk (queryable rays are finite,
  // and a zero direction component takes the tree).
  static __m128i orderKey(__m128 t) {
    const __m128i bits = _mm_castps_si128(t);
    return _mm_xor_si128(bits, _mm_srli_epi32(_mm_srai_epi32(bits, 31), 1));
  }
#endif
  static constexpr std::int32_t kInfinityKey = 0x7f800000;  // orderKey(+infinity)
  [[nodiscard]] std::uint32_t index(std::uint32_t x, std::uint32_t y, std::uint32_t z) const {
    return (z * dims[1] + y) * dims[0] + x;
  }
};

}  // namespace duplex::toplevel_detail
