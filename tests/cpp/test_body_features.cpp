// A body's corners and edges against cloth triangles (contact/body_features.h): the feature
// points of a box and the feature-triangle test against hand-computed answers, and a box's
// corner pushed into a taut sheet, whose edges must never cross a cloth triangle (checked
// with a segment-triangle test written here).
#include <gtest/gtest.h>

#include "contact/body_features.h"
#include "levelset/signed_distance.h"
#include "test_support.h"
#include "world/world.h"

#include <cmath>

using namespace simbake;

// half extents 0.5, spacing 0.25: each 1 m edge in 4 pieces, so 3 inner points per edge and
// the 8 corners: 44 points, all on two faces at once (two coordinates at +-0.5, phi = 0),
// each normal the unit sum of its faces' normals
TEST(BodyFeatures, BoxEdgePointsAndNormals) {
  std::vector<Vec3> points, normals;
  box_edge_features(Vec3::Constant(0.5), 0.25, points, normals);
  ASSERT_EQ(points.size(), 44u);
  const BoxDistance box(Vec3::Constant(1.0));
  for (size_t i = 0; i < points.size(); ++i) {
    EXPECT_NEAR(box.phi(points[i]), 0.0, 1e-15);
    int on_faces = 0;
    Vec3 expected = Vec3::Zero();
    for (int a = 0; a < 3; ++a) {
      if (std::abs(std::abs(points[i][a]) - 0.5) < 1e-15) {
        ++on_faces;
        expected[a] = points[i][a] > 0 ? 1.0 : -1.0;
      }
    }
    EXPECT_GE(on_faces, 2);
    EXPECT_LT((normals[i] - expected.normalized()).norm(), 1e-15);
  }
}

// the triangle (0,0,0), (1,0,0), (0,0,1) in the plane y = 0; h = 5 mm, band 5 cm
TEST(BodyFeatures, FeatureAgainstTriangle) {
  const Vec3 a(0, 0, 0), b(1, 0, 0), c(0, 0, 1), up(0, 1, 0);
  Vec3 w, normal;
  double phi;
  // 3 mm under the plane, facing up: the plane is 3 mm ahead (closer than h); projection at
  // (0.2, 0, 0.3) = 0.5 a + 0.2 b + 0.3 c
  ASSERT_TRUE(feature_against_triangle(Vec3(0.2, -0.003, 0.3), up, a, b, c, 0.005, 0.05, w, normal, phi));
  EXPECT_NEAR(phi, 0.003, 1e-15);
  EXPECT_LT((w - Vec3(0.5, 0.2, 0.3)).norm(), 1e-14);
  EXPECT_LT((normal - up).norm(), 1e-15);
  // 1 cm through the plane: the plane is 1 cm behind it (within the band)
  ASSERT_TRUE(feature_against_triangle(Vec3(0.2, 0.01, 0.3), up, a, b, c, 0.005, 0.05, w, normal, phi));
  EXPECT_NEAR(phi, -0.01, 1e-15);
  // the normal turns towards the feature's: the same feature facing down sees the plane 1 cm ahead
  ASSERT_FALSE(feature_against_triangle(Vec3(0.2, 0.01, 0.3), -up, a, b, c, 0.005, 0.05, w, normal, phi));
  EXPECT_NEAR(phi, 0.01, 1e-15);
  // far under the plane (beyond the band), outside the triangle, far above: none
  EXPECT_FALSE(feature_against_triangle(Vec3(0.2, 0.1, 0.3), up, a, b, c, 0.005, 0.05, w, normal, phi));
  EXPECT_FALSE(feature_against_triangle(Vec3(0.8, -0.001, 0.8), up, a, b, c, 0.005, 0.05, w, normal, phi));
  EXPECT_FALSE(feature_against_triangle(Vec3(0.2, -0.006, 0.3), up, a, b, c, 0.005, 0.05, w, normal, phi));
}

namespace {

// whether segment (p, q) crosses triangle (a, b, c) strictly (ends on opposite sides of the
// plane, the crossing inside the triangle by barycentric coordinates)
bool segment_crosses(const Vec3& p, const Vec3& q, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 n = (b - a).cross(c - a);
  const double dp = n.dot(p - a), dq = n.dot(q - a);
  if (!((dp > 0 && dq < 0) || (dp < 0 && dq > 0))) return false;
  const Vec3 x = p + (q - p) * (dp / (dp - dq));
  const double area = n.squaredNorm();
  const double u = (b - x).cross(c - x).dot(n) / area, v = (c - x).cross(a - x).dot(n) / area;
  return u > 0 && v > 0 && u + v < 1;
}

}  // namespace

// A 1 m sheet (5 cm edges) pinned along its border, a 20 cm kinematic box turned corner down
// and driven 16 cm down into it at 0.4 m/s, its corner over the inside of a triangle (no
// vertex under it): the corner must push the sheet down (its middle sinks > 5 cm) and no
// box edge may cross a cloth triangle at any step
TEST(BodyFeatures, BoxCornerNeverPokesThroughATautSheet) {
  World world;
  const int n = 21;
  ClothDesc sheet = test::grid_cloth(n, n, 1.0, 1.0, Vec3(-0.5, 1.0, -0.5));
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      if (i == 0 || j == 0 || i == n - 1 || j == n - 1) sheet.pinned.push_back(j * n + i);
    }
  }
  world.add_cloth(sheet, 0.3, 0.005, false);
  // the rotation taking the corner (-1, -1, -1) / sqrt(3) to -y
  const Vec3 corner_dir = -Vec3::Ones().normalized();
  const Quat turn = Quat::FromTwoVectors(corner_dir, -Vec3::UnitY());
  BodyDesc box = test::box_body(Vec3::Constant(0.2), 1.0, Vec3::Zero());
  box.kinematic = true;
  box.orientation = turn;
  const Vec3 corner = turn * Vec3::Constant(-0.1);
  box.origin = Vec3(0.0125, 1.04, 0.0175) - corner;
  box.linear_velocity = Vec3(0.0, -0.4, 0.0);
  world.add_body(box);
  std::vector<std::array<Vec3, 2>> edges;
  for (int a = 0; a < 8; ++a) {
    for (int b = a + 1; b < 8; ++b) {
      if (__builtin_popcount(a ^ b) != 1) continue;
      const auto at = [](int k) { return Vec3((k & 1) ? 0.1 : -0.1, (k & 2) ? 0.1 : -0.1, (k & 4) ? 0.1 : -0.1); };
      edges.push_back({at(a), at(b)});
    }
  }
  int crossings = 0;
  for (int step = 0; step < 96; ++step) {  // 0.4 s
    world.step(1.0 / 240.0);
    const Pose pose = mesh_pose(world.body_def(0), world.body_state(0));
    const Points& x = world.cloth(0).positions();
    const Triangles& t = world.cloth(0).triangles();
    for (const auto& e : edges) {
      const Vec3 p = pose.apply(e[0]), q = pose.apply(e[1]);
      for (int k = 0; k < t.rows(); ++k) {
        crossings += segment_crosses(p, q, x.row(t(k, 0)).transpose(), x.row(t(k, 1)).transpose(),
                                     x.row(t(k, 2)).transpose());
      }
    }
  }
  EXPECT_LT(world.cloth(0).positions()((n / 2) * n + n / 2, 1), 0.95);
  EXPECT_EQ(crossings, 0);
}
