// The reduction of a pair's contact points: a flat contact keeps the corners that span it,
// points that push different ways keep their own groups, and the choice is deterministic.
#include <gtest/gtest.h>

#include "rigid/contact_points.h"

#include <algorithm>

using namespace simbake;

namespace {

Penetration point(double x, double z, double phi, const Vec3& n = Vec3::UnitY()) {
  Penetration p{0, 1, Vec3(x, 0.0, z), n, phi, Vec3(x, 0.0, z)};
  return p;
}

}  // namespace

TEST(ContactPoints, FaceOnFaceKeepsItsFourCorners) {
  // a 5 x 5 grid of points on a square face, the corner (-1, -1) deepest
  std::vector<Penetration> points;
  for (int i = 0; i < 5; ++i)
    for (int k = 0; k < 5; ++k) points.push_back(point(-1.0 + 0.5 * i, -1.0 + 0.5 * k, -1e-3 + 1e-6 * (i + k)));
  std::stable_sort(points.begin(), points.end(), deeper);
  reduce_contact_points(points);
  ASSERT_EQ(points.size(), 4u);
  EXPECT_EQ(points[0].x, Vec3(-1.0, 0.0, -1.0));  // the deepest first
  for (const Penetration& p : points) {
    EXPECT_DOUBLE_EQ(std::abs(p.x.x()), 1.0);  // every kept point a corner
    EXPECT_DOUBLE_EQ(std::abs(p.x.z()), 1.0);
  }
}

TEST(ContactPoints, OppositeNormalsKeepTheirOwnGroups) {
  // an edge caught on a side face: points pushing up and points pushing sideways
  std::vector<Penetration> points;
  for (int i = 0; i < 6; ++i) points.push_back(point(0.2 * i, 0.0, -2e-3 + 1e-5 * i));
  for (int i = 0; i < 6; ++i) points.push_back(point(0.0, 0.2 * i, -1e-3 + 1e-5 * i, Vec3::UnitX()));
  std::stable_sort(points.begin(), points.end(), deeper);
  reduce_contact_points(points);
  const auto sideways = std::count_if(points.begin(), points.end(), [](const Penetration& p) { return p.n.x() > 0.5; });
  EXPECT_GE(sideways, 1);
  EXPECT_GE(static_cast<long>(points.size()) - sideways, 1);
  EXPECT_LE(points.size(), 8u);
}

TEST(ContactPoints, FewPointsAreKeptAsTheyAre) {
  std::vector<Penetration> points{point(0.0, 0.0, -2e-3), point(1.0, 0.0, -1e-3), point(0.0, 1.0, -5e-4)};
  reduce_contact_points(points);
  ASSERT_EQ(points.size(), 3u);
  EXPECT_EQ(points[2].x, Vec3(0.0, 0.0, 1.0));
}
