// The cloth against itself (cloth/self_collision.h): what it must guarantee is checked with
// the crossing count of geometry/triangle_intersection.h, written apart from it.
#include <gtest/gtest.h>

#include "cloth/self_collision.h"
#include "geometry/triangle_intersection.h"
#include "test_support.h"

#include <random>

using namespace simbake;
using namespace simbake::test;

namespace {

// sign of the volume ((b - a) x (c - a)) . (p - a): which side of abc p is on
double side(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) { return (b - a).cross(c - a).dot(p - a); }

Vec3 momentum(const Points& v, const Eigen::VectorXd& inverse_mass) {
  Vec3 m = Vec3::Zero();
  for (Eigen::Index k = 0; k < v.rows(); ++k) m += v.row(k).transpose() / inverse_mass[k];
  return m;
}

// a folded grid: rows z < 0.5 flat on y = 0, the rest turned back over them at height
// `gap` (the fold a half circle), so the upper layer lies over the lower one
ClothDesc folded_grid(int n, double gap) {
  ClothDesc d = grid_cloth(n, n, 1.0, 1.0);
  for (Eigen::Index k = 0; k < d.rest.rows(); ++k) {
    const double z = d.rest(k, 2);
    if (z > 0.5) {
      const double angle = std::min(M_PI, (z - 0.5) / (gap / 2));  // round the fold, then flat
      const double along = std::max(0.0, (z - 0.5) - M_PI * gap / 2);
      d.rest(k, 1) = gap / 2 - gap / 2 * std::cos(angle);
      d.rest(k, 2) = 0.5 + gap / 2 * std::sin(angle) - along;
    }
  }
  return d;
}

}  // namespace

TEST(SelfCollision, PointStoppedAtATriangle) {
  // a point 0.1 m above a triangle's middle, moving down 0.3 m in the step: it must stay above
  Points x(4, 3), v(4, 3);
  x << 0, 0, 0, 1, 0, 0, 0, 0, 1, 0.25, 0.1, 0.25;
  v.setZero();
  v.row(3) << 0.0, -30.0, 0.0;
  Triangles t(1, 3);
  t << 0, 2, 1;  // the point belongs to no triangle: a loose vertex of the cloth
  const Eigen::VectorXd inverse_mass = Eigen::VectorXd::Ones(4);
  SelfCollision self(t, 4);
  SelfCollisionStatistics stats;
  const double dt = 0.01;
  const Vec3 before = momentum(v, inverse_mass);
  self.resolve(x, v, inverse_mass, dt, SelfCollisionSettings{0.005, 0.0}, stats);
  const Points end = x + dt * v;
  EXPECT_GT(side(end.row(3), end.row(0), end.row(2), end.row(1)), 0.0);
  EXPECT_GT(stats.collisions, 0);
  EXPECT_LT((momentum(v, inverse_mass) - before).norm(), 1e-12);
  // the approach is stopped, not reversed (inelastic): the point moves with the triangle's
  // point under it (weights 0.5, 0.25, 0.25 of vertices 0, 1, 2)
  const double under = 0.5 * v(0, 1) + 0.25 * v(1, 1) + 0.25 * v(2, 1);
  EXPECT_NEAR(v(3, 1), under, 0.1);
}

TEST(SelfCollision, CrossingEdgesStopped) {
  // edge (0, 1) along x at y = 0.05 falls through edge (2, 3) along z at y = 0 in one step
  Points x(6, 3), v(6, 3);
  x << -1, 0.05, 0, 1, 0.05, 0, 0, 0, -1, 0, 0, 1, 0, 0.5, 5, 5, -0.5, 0;
  v.setZero();
  v.row(0) << 0, -10, 0;
  v.row(1) << 0, -10, 0;
  Triangles t(2, 3);
  t << 0, 1, 4, 2, 3, 5;  // two triangles sloping away from each other but for those two edges
  ASSERT_TRUE(intersecting_triangle_pairs(x, t).empty());
  const Eigen::VectorXd inverse_mass = Eigen::VectorXd::Ones(6);
  SelfCollision self(t, 6);
  SelfCollisionStatistics stats;
  const double dt = 0.01;
  self.resolve(x, v, inverse_mass, dt, SelfCollisionSettings{0.005, 0.0}, stats);
  const Points end = x + dt * v;
  // edge 0-1 still above edge 2-3 where they cross (x = 0, z = 0)
  const double y_upper = 0.5 * (end(0, 1) + end(1, 1)), y_lower = 0.5 * (end(2, 1) + end(3, 1));
  EXPECT_GT(y_upper, y_lower);
  EXPECT_TRUE(intersecting_triangle_pairs(end, t).empty());
  EXPECT_GT(stats.collisions, 0);
}

TEST(SelfCollision, FoldedClothLandsOnItselfWithoutCrossing) {
  // the upper layer of a folded cloth falls onto the lower one, held flat in the air by pins
  // (no ground: nothing presses the two layers into one plane): without self-collision it
  // falls through (so the test can fail); with it, no crossing at any step
  for (bool on : {false, true}) {
    World world;
    ClothDesc d = folded_grid(21, 0.12);
    for (Eigen::Index k = 0; k < d.rest.rows(); ++k) {
      if (d.rest(k, 2) <= 0.5 && d.rest(k, 1) == 0.0) d.pinned.push_back(static_cast<int>(k));
    }
    d.material.stretch_stiffness = 2000.0;
    world.add_cloth(d, 0.3, 0.005, on);
    int worst = 0;
    for (int step = 0; step < 120; ++step) {
      world.step(1.0 / 240.0);
      const Cloth& c = world.cloth(0);
      worst = std::max(worst, static_cast<int>(intersecting_triangle_pairs(c.positions(), c.triangles()).size()));
      if (on) ASSERT_EQ(worst, 0) << "step " << step;
    }
    if (!on) EXPECT_GT(worst, 20);
    if (on) EXPECT_GT(world.statistics().self_collision.repulsions + world.statistics().self_collision.collisions, 0);
  }
}

TEST(SelfCollision, ShakenClothNeverCrosses) {
  // a flat cloth given large random velocities (no gravity, no ground): layers fold through
  // each other at once without self-collision; with it, never, and momentum is kept
  std::mt19937 rng(11);
  std::normal_distribution<double> speed(0.0, 3.0);
  World world(WorldSettings{Vec3::Zero()});
  ClothDesc d = grid_cloth(17, 17, 1.0, 1.0);
  d.material.stretch_stiffness = 500.0;
  world.add_cloth(d, 0.3, 0.01);
  Cloth& cloth = world.cloth(0);
  for (Eigen::Index k = 0; k < cloth.velocities().rows(); ++k) {
    cloth.velocities().row(k) << speed(rng), speed(rng), speed(rng);
  }
  Eigen::VectorXd inverse_mass = cloth.masses().cwiseInverse();
  const Vec3 start = momentum(cloth.velocities(), inverse_mass);
  for (int step = 0; step < 100; ++step) {
    world.step(1.0 / 120.0);
    ASSERT_TRUE(intersecting_triangle_pairs(cloth.positions(), cloth.triangles()).empty()) << "step " << step;
  }
  // internal forces and self-collision impulses are all internal: momentum within round-off
  // (relative to the momentum scale: total mass x the mean speed)
  const double scale = cloth.masses().sum() * 3.0;
  EXPECT_LT((momentum(cloth.velocities(), inverse_mass) - start).norm(), 1e-6 * scale);
  std::printf("  shaken cloth: %lld repulsions, %lld collision impulses, %lld zone rounds, %lld stills\n",
              world.statistics().self_collision.repulsions, world.statistics().self_collision.collisions,
              world.statistics().self_collision.zone_rounds, world.statistics().self_collision.stills);
}

TEST(SelfCollision, SameBitsAtAnyThreadCount) {
  // a folded cloth landing on itself and the ground, stepped frame by frame at 1 and at 2
  // worker threads: candidate search and pair tests run in parallel, in fixed chunks joined
  // in order, so the positions must agree to the last bit
  std::vector<Points> results;
  for (int threads : {1, 2}) {
    WorldSettings settings;
    settings.threads = threads;
    World world(settings);
    world.set_ground(GroundDef{0.0, 0.5, 0.0});
    ClothDesc d = folded_grid(33, 0.1);
    for (Eigen::Index k = 0; k < d.rest.rows(); ++k) d.rest(k, 1) += 0.3 + 0.05 * d.rest(k, 0);
    world.add_cloth(d, 0.3, 0.005);
    for (int frame = 0; frame < 24; ++frame) world.step_frame(1.0 / 24.0);
    EXPECT_GT(world.statistics().self_collision.repulsions, 0);
    results.push_back(world.cloth(0).positions());
  }
  EXPECT_TRUE(results[0] == results[1]);
}
