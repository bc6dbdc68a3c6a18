// The CIE 171:2006 cases in their short versions: every value within 4 standard errors plus the
// case's tolerance (0.5%, glass 0.2%) of its exact reference.

#include "CieCases.h"
#include "OpticsReference.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

namespace duplex::validation {
namespace {

void expectRows(const CaseResult& c) {
  double z2 = 0.0;
  for (const CaseRow& row : c.rows) {
    EXPECT_TRUE(row.passes()) << c.name << ", " << row.label << ": " << row.value << " +- " << row.stderr_value
                              << " against " << row.reference << " (z = " << row.z() << ")";
    z2 += row.z() * row.z();
  }
  std::printf("%s: %zu values, mean z^2 %.3f, %.2f s\n", c.name.c_str(), c.rows.size(), z2 / c.rows.size(), c.seconds);
  for (const std::string& note : c.notes) std::printf("  %s\n", note.c_str());
}

TEST(CieValidation, PointSourceOverFloorAndWall) { expectRows(pointSourceCase({})); }

TEST(CieValidation, AreaSourceOverFloor) { expectRows(areaSourceCase({})); }

TEST(CieValidation, AreaSourceAtPoints) { expectRows(areaSourcePointsCase({})); }

TEST(CieValidation, ObstructionShadowsThePointSource) { expectRows(obstructionCase({})); }

TEST(CieValidation, BlackCubeGetsDirectLightOnly) { expectRows(blackCubeCase({})); }

TEST(CieValidation, DiffuseCubesInterReflectWithoutBias) {
  for (const double rho : {0.2, 0.5, 0.8, 0.95}) expectRows(diffuseCubeCase(rho, {}));
}

TEST(CieValidation, ClearGlassAtEveryAngle) { expectRows(clearGlassCase({})); }

TEST(CieValidation, DaylightThroughRoofAndFacadeOpenings) {
  expectRows(daylightOpeningCase(true, {}));
  expectRows(daylightOpeningCase(false, {}));
  expectRows(daylightSunCase({}));
}

TEST(CieValidation, ReferencesAgreeWithIndependentForms) {
  // The parallel-rectangle exchange area of two unit squares 1 apart (the tabulated 0.19982),
  // additive over a split of one rectangle, and equal to the point factor integrated over a cell;
  // the CIE curve at normal incidence.
  EXPECT_NEAR(test::parallelRectanglesExchange(0, 1, 0, 1, 0, 1, 0, 1, 1.0), 0.199825, 1e-6);
  const double whole = test::parallelRectanglesExchange(-2, 2, -2, 2, -0.5, 0.5, -0.5, 0.5, 3.0);
  double parts = 0.0;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j)
      parts += test::parallelRectanglesExchange(-2 + i, -1 + i, -2 + j, -1 + j, -0.5, 0.5, -0.5, 0.5, 3.0);
  EXPECT_NEAR(parts, whole, 1e-12 * whole);
  // A floor cell against the point-to-panel factor integrated over the cell (midpoint rule,
  // 200 x 200 points: relative error of order 1e-6).
  double integral = 0.0;
  const int m = 200;
  for (int i = 0; i < m; ++i)
    for (int j = 0; j < m; ++j) {
      const double x = 0.5 + 0.5 * (i + 0.5) / m, y = 1.0 + 0.5 * (j + 0.5) / m;
      integral += test::pointToParallelRectangle(-0.5 - x, 0.5 - x, -0.5 - y, 0.5 - y, 3.0) * 0.25 / (m * m);
    }
  EXPECT_NEAR(test::parallelRectanglesExchange(0.5, 1.0, 1.0, 1.5, -0.5, 0.5, -0.5, 0.5, 3.0), integral,
              1e-5 * integral);
  EXPECT_NEAR(test::cieClearGlassTransmittance(1.0), 0.87881, 1e-5);
}

}  // namespace
}  // namespace duplex::validation
