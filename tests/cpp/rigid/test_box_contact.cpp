// Box against box (rigid/box_contact.h): answers worked out by hand for faces, corners and
// crossing edges, and on random pairs checks written apart from the code: each contact
// point is on box a's surface and as deep in box b as it says (the analytic BoxDistance),
// the depth is the separating-axis depth found by brute force over directions, and the
// pair swapped gives the same depth with the normal reversed.
#include "levelset/signed_distance.h"
#include "rigid/box_contact.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace simbake {
namespace {

OrientedBox box(const Vec3& centre, const Mat3& rotation, const Vec3& size) {
  return OrientedBox{centre, rotation, 0.5 * size};
}

Mat3 turn(const Vec3& axis, double angle) { return Eigen::AngleAxisd(angle, axis.normalized()).toRotationMatrix(); }

// phi of world point x in box b (analytic, independent of the contact code)
double phi_in(const OrientedBox& b, const Vec3& x) {
  return BoxDistance(2.0 * b.half).phi(b.rotation.transpose() * (x - b.center));
}

TEST(BoxContact, BoxRestingOnABoxTouchesAtTheFourCornersOfItsBottom) {
  const OrientedBox lower = box(Vec3(0, 0.5, 0), Mat3::Identity(), Vec3::Ones());
  const OrientedBox upper = box(Vec3(0.2, 1.24, 0.1), Mat3::Identity(), Vec3(0.5, 0.5, 0.5));
  BoxContact c;
  ASSERT_TRUE(box_box_contact(upper, lower, 0.0, c));
  EXPECT_FALSE(c.edge_edge);
  EXPECT_NEAR((c.normal - Vec3::UnitY()).norm(), 0.0, 1e-15);
  EXPECT_NEAR(c.depth, 0.01, 1e-12);
  ASSERT_EQ(c.count, 4);
  for (int i = 0; i < c.count; ++i) {
    EXPECT_NEAR(c.points[i].depth, 0.01, 1e-12);
    EXPECT_NEAR(c.points[i].x.y(), 0.99, 1e-12);   // the upper box's bottom face
    EXPECT_NEAR(std::abs(c.points[i].x.x() - 0.2), 0.25, 1e-12);
    EXPECT_NEAR(std::abs(c.points[i].x.z() - 0.1), 0.25, 1e-12);
  }
}

TEST(BoxContact, ALargeBoxOnASmallOneIsClippedToTheSmallTop) {
  // the reference face is the small box's top; the large box's bottom is clipped to it
  const OrientedBox small = box(Vec3(0, 0.25, 0), Mat3::Identity(), Vec3(0.5, 0.5, 0.5));
  const OrientedBox large = box(Vec3(0, 0.98, 0), Mat3::Identity(), Vec3(2, 1, 2));
  BoxContact c;
  ASSERT_TRUE(box_box_contact(large, small, 0.0, c));
  EXPECT_NEAR((c.normal - Vec3::UnitY()).norm(), 0.0, 1e-15);
  ASSERT_EQ(c.count, 4);
  for (int i = 0; i < c.count; ++i) {
    EXPECT_NEAR(c.points[i].depth, 0.02, 1e-12);
    EXPECT_NEAR(c.points[i].x.y(), 0.48, 1e-12);   // on the large box's bottom
    EXPECT_NEAR(std::abs(c.points[i].x.x()), 0.25, 1e-12);
  }
}

TEST(BoxContact, ATiltedBoxTouchesWithOneCorner) {
  // a unit cube turned so that a body diagonal points down: its lowest corner is sqrt(3)/2
  // below its centre
  const Mat3 R = Eigen::Quaterniond::FromTwoVectors(Vec3(1, 1, 1).normalized(), -Vec3::UnitY()).toRotationMatrix();
  const OrientedBox floor = box(Vec3(0, -1, 0), Mat3::Identity(), Vec3(4, 2, 4));
  const OrientedBox cube = box(Vec3(0, std::sqrt(3.0) / 2 - 0.03, 0), R, Vec3::Ones());
  BoxContact c;
  ASSERT_TRUE(box_box_contact(cube, floor, 0.0, c));
  ASSERT_EQ(c.count, 1);
  EXPECT_NEAR(c.depth, 0.03, 1e-12);
  EXPECT_NEAR(c.points[0].depth, 0.03, 1e-12);
  EXPECT_NEAR((c.points[0].x - Vec3(0, -0.03, 0)).norm(), 0.0, 1e-12);
}

TEST(BoxContact, CrossingEdgesGiveOnePointBetweenThem) {
  // two unit cubes, each turned 45 degrees so that an edge points at the other, the lower
  // one's top edge along x, the upper one's bottom edge along z: they cross by 2 (sqrt(2)/2)
  // minus the distance of the centres
  const double reach = std::sqrt(0.5), gap = 2 * reach - 0.04;
  const OrientedBox lower = box(Vec3::Zero(), turn(Vec3::UnitX(), M_PI / 4), Vec3::Ones());
  const OrientedBox upper = box(Vec3(0, gap, 0), turn(Vec3::UnitZ(), M_PI / 4), Vec3::Ones());
  BoxContact c;
  ASSERT_TRUE(box_box_contact(upper, lower, 0.0, c));
  EXPECT_TRUE(c.edge_edge);
  EXPECT_NEAR(c.depth, 0.04, 1e-12);
  EXPECT_NEAR((c.normal - Vec3::UnitY()).norm(), 0.0, 1e-12);
  ASSERT_EQ(c.count, 1);
  EXPECT_NEAR((c.points[0].x - Vec3(0, gap - reach, 0)).norm(), 0.0, 1e-12);   // the upper edge's lowest point
}

TEST(BoxContact, BoxesApartHaveNoContactUnlessWithinTheMargin) {
  const OrientedBox a = box(Vec3::Zero(), Mat3::Identity(), Vec3::Ones());
  const OrientedBox b = box(Vec3(1.05, 0, 0), Mat3::Identity(), Vec3::Ones());
  BoxContact c;
  EXPECT_FALSE(box_box_contact(a, b, 0.0, c));
  EXPECT_FALSE(box_box_contact(a, b, 0.04, c));
  ASSERT_TRUE(box_box_contact(a, b, 0.06, c));
  EXPECT_NEAR(c.depth, -0.05, 1e-12);
  for (int i = 0; i < c.count; ++i) EXPECT_NEAR(c.points[i].depth, -0.05, 1e-12);
}

// The separating-axis depth by brute force: the smallest overlap of the projections over many
// directions (a fine sphere of directions plus the 15 candidate axes computed here again)
double brute_force_depth(const OrientedBox& a, const OrientedBox& b) {
  const auto overlap = [&](const Vec3& L) {
    double ra = 0, rb = 0;
    for (int k = 0; k < 3; ++k) {
      ra += a.half[k] * std::abs(L.dot(a.rotation.col(k)));
      rb += b.half[k] * std::abs(L.dot(b.rotation.col(k)));
    }
    return ra + rb - std::abs(L.dot(b.center - a.center));
  };
  double best = INFINITY;
  for (int i = 0; i < 3; ++i) {
    best = std::min({best, overlap(a.rotation.col(i)), overlap(b.rotation.col(i))});
    for (int j = 0; j < 3; ++j) {
      const Vec3 L = a.rotation.col(i).cross(b.rotation.col(j));
      if (L.norm() > 1e-6) best = std::min(best, overlap(L.normalized()));
    }
  }
  return best;
}

TEST(BoxContact, RandomPairsAgreeWithIndependentChecks) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0), size(0.3, 1.2);
  int tested = 0, edges = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    const Mat3 Ra = Eigen::Quaterniond(u(rng), u(rng), u(rng), u(rng)).normalized().toRotationMatrix();
    const Mat3 Rb = Eigen::Quaterniond(u(rng), u(rng), u(rng), u(rng)).normalized().toRotationMatrix();
    const OrientedBox a = box(Vec3::Zero(), Ra, Vec3(size(rng), size(rng), size(rng)));
    const OrientedBox b = box(Vec3(u(rng), u(rng), u(rng)) * 1.2, Rb, Vec3(size(rng), size(rng), size(rng)));
    BoxContact ab, ba;
    const bool touching = box_box_contact(a, b, 0.0, ab);
    const double depth = brute_force_depth(a, b);
    if (depth < 0.0) {
      EXPECT_FALSE(touching);
      continue;
    }
    if (depth < 1e-9) continue;  // grazing: either answer is right
    ASSERT_TRUE(touching) << trial;
    ++tested;
    edges += ab.edge_edge;
    // the edge-only query answers the same, and only for edge contacts
    BoxContact edge;
    ASSERT_EQ(box_edge_contact(a, b, 0.0, edge), ab.edge_edge) << trial;
    if (ab.edge_edge) EXPECT_EQ((edge.points[0].x - ab.points[0].x).norm(), 0.0);
    ASSERT_TRUE(box_box_contact(b, a, 0.0, ba));
    // the depth is the least overlap, or (a face preferred) within 5% of it
    EXPECT_GE(ab.depth, depth - 1e-12);
    EXPECT_LE(ab.depth, depth / 0.95 + 1e-6);
    EXPECT_NEAR(ab.depth, ba.depth, 1e-12);
    EXPECT_NEAR((ab.normal + ba.normal).norm(), 0.0, 1e-9);
    // moving a out along the normal by the depth separates the boxes
    OrientedBox moved = a;
    moved.center += (ab.depth + 1e-9) * ab.normal;
    EXPECT_LT(brute_force_depth(moved, b), 1e-8);
    for (int i = 0; i < ab.count; ++i) {
      const BoxContactPoint& p = ab.points[i];
      EXPECT_NEAR(phi_in(a, p.x), 0.0, 1e-9) << trial;            // on a's surface
      EXPECT_LE(p.depth, ab.depth + 1e-9);
      if (!ab.edge_edge) {
        // as deep in b as it says: b's surface is `depth` away along the normal (the point
        // lies inside b's face's prism)
        EXPECT_NEAR(phi_in(b, p.x + p.depth * ab.normal), 0.0, 1e-9) << trial;
      }
    }
  }
  EXPECT_GT(tested, 500);
  EXPECT_GT(edges, 20);
}

}  // namespace
}  // namespace simbake
