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

// A triangle lying on the ground, y = 0 (vertices 0-2), and a point (vertex 3) `height` above
// its centroid; each of unit mass
struct PointOverGroundTriangle {
  explicit PointOverGroundTriangle(double height) : x(4, 3), t(1, 3), inverse_mass(Eigen::VectorXd::Ones(4)) {
    x << 0, 0, 0, 1, 0, 0, 0, 0, 1, 1.0 / 3, height, 1.0 / 3;
    t << 0, 2, 1;
  }
  Points x;
  Triangles t;
  Eigen::VectorXd inverse_mass;
};

TEST(SelfCollision, ARepulsionLeavesAVertexOnItsSupport) {
  // a triangle lying on the ground (its vertices' support: the ground's normal, +y) and a
  // point 2 mm above its middle coming down at 1 m/s, inside the 5 mm thickness: the
  // repulsion stops the point's approach and pushes it up by 0.1 (h - d) / dt. Unsupported,
  // the triangle takes half the change (equal masses, weights 1 and 1/3 x 3): pushed down,
  // into the ground. Supported, it keeps its velocity and the point takes the whole change
  const double h = 0.005, dt = 0.01, d = 0.002;
  const PointOverGroundTriangle scene(d);
  const Points& x = scene.x;
  const Triangles& t = scene.t;
  const Eigen::VectorXd& inverse_mass = scene.inverse_mass;
  Points v(4, 3);
  const double target = 0.1 * (h - d) / dt;  // the relative normal velocity a repulsion sets
  for (const bool supported : {false, true}) {
    v.setZero();
    v(3, 1) = -1.0;
    std::vector<Vec3> support(4, Vec3::Zero());
    if (supported) support[0] = support[1] = support[2] = Vec3(0.0, 2.0, 0.0);  // any length
    SelfCollisionSettings settings{h, 0.0};
    settings.support = &support;
    SelfCollision self(t, 4);
    SelfCollisionStatistics stats;
    self.repel(x, v, inverse_mass, dt, settings, stats);
    EXPECT_EQ(stats.repulsions, 1);
    const double under = (v(0, 1) + v(1, 1) + v(2, 1)) / 3;
    EXPECT_NEAR(v(3, 1) - under, target, 1e-12) << supported;
    if (supported) {
      for (int k = 0; k < 3; ++k) EXPECT_EQ(v.row(k).norm(), 0.0) << k;
      EXPECT_NEAR(v(3, 1), target, 1e-12);
    } else {
      // the change shared by inverse mass x weight: denominator 1 + 3 (1/3)^2 = 4/3
      EXPECT_NEAR(under, -(target + 1.0) / (4.0 / 3.0) / 3, 1e-12);
      EXPECT_LT(under, 0.0);
    }
  }
}

TEST(SelfCollision, ImpulsesAndZonesLeaveAVertexOnItsSupport) {
  // the same triangle on the ground, the point 2 mm above it now falling at 1 m/s through it
  // within the step (10 mm). The collision impulse (continuous detection) of a supported
  // triangle leaves it still, the point alone reversed; an impact zone of the four, whose
  // rigid motion keeps their momentum (all four down at 1/4 m/s), would take the triangle
  // into the ground: supported, the zone holds still instead
  const double dt = 0.01;
  const PointOverGroundTriangle ground(0.002);
  Points v(4, 3);
  for (const bool supported : {false, true}) {
    std::vector<Vec3> support(4, Vec3::Zero());
    if (supported) support[0] = support[1] = support[2] = Vec3(0.0, 1.0, 0.0);
    SelfCollisionSettings settings{0.005, 0.0};
    settings.support = &support;
    SelfCollisionStatistics stats;
    {
      v.setZero();
      v(3, 1) = -1.0;
      SelfCollision self(ground.t, 4);
      EXPECT_FALSE(self.collide(ground.x, v, ground.inverse_mass, dt, settings, stats, 1));
      EXPECT_EQ(stats.collisions, 1);
      const double under = (v(0, 1) + v(1, 1) + v(2, 1)) / 3;
      EXPECT_GT(v(3, 1), under);  // the approach reversed
      if (supported) {
        for (int k = 0; k < 3; ++k) EXPECT_EQ(v.row(k).norm(), 0.0) << k;
      } else {
        EXPECT_LT(under, 0.0);
      }
    }
    {
      v.setZero();
      v(3, 1) = -1.0;
      SelfCollision self(ground.t, 4);
      self.impact_zones(ground.x, v, ground.inverse_mass, dt, settings, stats);
      EXPECT_GE(stats.zone_rounds, 1);
      for (int k = 0; k < 4; ++k) {
        EXPECT_NEAR(v(k, 1), supported ? 0.0 : -0.25, 1e-12) << k << " " << supported;
        EXPECT_NEAR(v(k, 0), 0.0, 1e-12);
        EXPECT_NEAR(v(k, 2), 0.0, 1e-12);
      }
    }
  }
}

TEST(SelfCollision, AHeldPairLeftWithOneLightCornerIsNotFlung) {
  // the point 2 mm over the triangle, both held against the repulsion's push (the triangle's
  // vertices 0 and 1 by the ground under them, the point by a still surface over it): the
  // triangle's vertex 2 alone can take the change, by 1 / w_2 times it. Over the triangle's
  // far side (w_2 = 0.01) that would fling it at 100x the change: the repulsion is left
  // out. Over its middle (w_2 = 0.6) vertex 2 takes it all, 1 / 0.6 times
  const double h = 0.005, dt = 0.01, d = 0.002;
  const double target = 0.1 * (h - d) / dt;
  PointOverGroundTriangle scene(d);
  std::vector<Vec3> support(4, Vec3::Zero());
  support[0] = support[1] = Vec3(0.0, 1.0, 0.0);
  support[3] = Vec3(0.0, -1.0, 0.0);
  SelfCollisionSettings settings{h, 0.0};
  settings.support = &support;
  for (const double w2 : {0.01, 0.6}) {
    scene.x.row(3) << 0.2, d, w2;  // barycentric weight of vertex 2 (0, 0, 1): its z
    Points v = Points::Zero(4, 3);
    SelfCollision self(scene.t, 4);
    SelfCollisionStatistics stats;
    self.repel(scene.x, v, scene.inverse_mass, dt, settings, stats);
    for (const int k : {0, 1, 3}) EXPECT_EQ(v.row(k).norm(), 0.0) << k;
    if (w2 < 0.25) {
      EXPECT_EQ(stats.repulsions, 0);
      EXPECT_EQ(v.row(2).norm(), 0.0);
    } else {
      EXPECT_EQ(stats.repulsions, 1);
      EXPECT_NEAR(v(2, 1), -target / w2, 1e-12);
    }
  }
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
    world.add_cloth(test::with_contacts(d, 0.3, 0.005, on));
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
  world.add_cloth(test::with_contacts(d, 0.3, 0.01));
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
  const StepStatistics all = world.statistics(false);
  const SelfCollisionStatistics& stats = all.self_collision;
  std::printf("  shaken cloth: %lld repulsions, %lld collision impulses, %lld zone rounds, %lld stills, "
              "%lld over budget, peaks: %lld candidates, %lld pairs visited a step, %lld zone rounds a call; "
              "%lld steps gave\n", stats.repulsions, stats.collisions, stats.zone_rounds, stats.stills, stats.over_budget,
              stats.candidate_peak, stats.pass_peak, stats.zone_round_peak, world.statistics().cloth_gave);
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
    world.add_cloth(test::with_contacts(d, 0.3, 0.005));
    for (int frame = 0; frame < 24; ++frame) world.step_frame(1.0 / 24.0);
    EXPECT_GT(world.statistics().self_collision.repulsions, 0);
    results.push_back(world.cloth(0).positions());
  }
  EXPECT_TRUE(results[0] == results[1]);
}

namespace {


}  // namespace

TEST(SelfCollision, NearPairsOfAFlatPivotNeverMeet) {
  // self_collision.h's argument for leaving near pairs out, checked by brute force: around
  // the middle vertex q of a 5 x 5 grid, bent and moved at random (up to an edge length and
  // more in a step), whenever q's triangles stay flat over the step (the Bernstein bound of
  // the header, written again here), no point next to q meets a triangle of q's and no edge
  // across one of them crosses another edge of q's. The moves that are not flat must make
  // such pairs meet, so that the check can fail.
  const ClothDesc d = grid_cloth(5, 5, 4.0, 4.0);
  const Triangles& t = d.triangles;
  const int q = 12;
  std::vector<int> fan, neighbours;
  for (Eigen::Index i = 0; i < t.rows(); ++i) {
    if (t(i, 0) == q || t(i, 1) == q || t(i, 2) == q) fan.push_back(static_cast<int>(i));
  }
  for (int i : fan) {
    for (int j = 0; j < 3; ++j) {
      if (t(i, j) != q && std::find(neighbours.begin(), neighbours.end(), t(i, j)) == neighbours.end()) neighbours.push_back(t(i, j));
    }
  }
  ASSERT_EQ(fan.size(), 6u);
  const auto on = [&](int i, int k) { return t(i, 0) == k || t(i, 1) == k || t(i, 2) == k; };
  std::vector<std::pair<bool, std::array<int, 4>>> pairs;
  for (int i : fan) {
    for (int p : neighbours) {
      if (!on(i, p)) pairs.push_back({true, {p, static_cast<int>(t(i, 0)), static_cast<int>(t(i, 1)), static_cast<int>(t(i, 2))}});
    }
    std::array<int, 2> across{};
    int count = 0;
    for (int j = 0; j < 3; ++j) {
      if (t(i, j) != q) across[count++] = t(i, j);
    }
    for (int w : neighbours) {
      if (!on(i, w)) pairs.push_back({false, {across[0], across[1], q, w}});
    }
  }
  ASSERT_EQ(pairs.size(), 48u);  // 6 triangles x 4 points and x 4 edges
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  int flat_moves = 0, other_moves = 0, met_flat = 0, met_other = 0;
  for (int trial = 0; trial < 4000; ++trial) {
    // the start: a gentle height field with in-plane jitter (free of crossings); the move:
    // every vertex displaced by up to `reach` edge lengths (from a little to enough to fold)
    const double reach = 0.1 + 1.4 * trial / 4000.0;
    Points x0 = d.rest, x1(d.rest.rows(), 3);
    for (Eigen::Index k = 0; k < x0.rows(); ++k) {
      x0(k, 0) += 0.2 * unit(rng);
      x0(k, 1) += 0.4 * unit(rng);
      x0(k, 2) += 0.2 * unit(rng);
      for (int a = 0; a < 3; ++a) x1(k, a) = x0(k, a) + reach * unit(rng);
    }
    Vec3 axis = Vec3::Zero();
    std::vector<std::array<Vec3, 3>> bernstein;
    for (int i : fan) {
      const Vec3 a0 = x0.row(t(i, 0)).transpose(), e1 = x0.row(t(i, 1)).transpose() - a0, e2 = x0.row(t(i, 2)).transpose() - a0;
      const Vec3 da = (x1.row(t(i, 0)) - x0.row(t(i, 0))).transpose();
      const Vec3 d1 = (x1.row(t(i, 1)) - x0.row(t(i, 1))).transpose() - da, d2 = (x1.row(t(i, 2)) - x0.row(t(i, 2))).transpose() - da;
      const Vec3 c0 = e1.cross(e2), c1 = e1.cross(d2) + d1.cross(e2), c2 = d1.cross(d2);
      bernstein.push_back({c0, c0 + 0.5 * c1, c0 + c1 + c2});
      axis += c0;
    }
    axis.normalize();
    bool flat = true;
    for (const auto& b : bernstein) {
      for (const Vec3& c : b) flat = flat && c.dot(axis) >= 0.1 * std::max({b[0].norm(), b[1].norm(), b[2].norm()});
    }
    int met = 0;
    for (const auto& [point, ids] : pairs) met += meet(point, ids, x0, x1);
    (flat ? flat_moves : other_moves) += 1;
    (flat ? met_flat : met_other) += met;
  }
  std::printf("  %d flat moves (near pairs met: %d), %d others (met: %d)\n", flat_moves, met_flat, other_moves, met_other);
  EXPECT_GT(flat_moves, 500);
  EXPECT_EQ(met_flat, 0);
  EXPECT_GT(met_other, 100);
}

TEST(SelfCollision, NearPairsAreCandidatesOnlyWhereTheSheetBends) {
  // a flat sheet falling and spinning in its plane makes none of its near pairs candidates;
  // one folded over sharply (a fold 2 cm across, its rows 5 cm apart) makes those along the fold
  for (bool folded : {false, true}) {
    const ClothDesc d = folded ? folded_grid(21, 0.02) : grid_cloth(21, 21, 1.0, 1.0);
    Points v(d.rest.rows(), 3);
    for (Eigen::Index k = 0; k < v.rows(); ++k) v.row(k) << -d.rest(k, 2), -2.0, d.rest(k, 0);
    SelfCollision self(d.triangles, static_cast<int>(d.rest.rows()));
    SelfCollisionStatistics stats;
    Points moved = v;
    self.resolve(d.rest, moved, Eigen::VectorXd::Ones(d.rest.rows()), 0.01, SelfCollisionSettings{0.005, 0.0}, stats);
    if (folded) {
      EXPECT_GT(stats.near_pairs, 0);
    } else {
      EXPECT_EQ(stats.near_pairs, 0);
      EXPECT_TRUE(moved == v);  // nothing near, nothing changed
    }
  }
}

namespace {

// a triangle of the cloth lying at rest in y = 0, and one obstacle: `obstacle`, moving at
// `velocity`; both in one set of arrays as SelfCollision takes them (the cloth's 3 vertices,
// then the obstacle's, of inverse mass 0)
struct ClothAndObstacle {
  Points x, v;
  Eigen::VectorXd inverse_mass;
  std::vector<ObstacleMotion> motion;
  ClothAndObstacle(const Points& cloth, const TriangleMesh& obstacle, const Vec3& velocity) {
    const Eigen::Index n = cloth.rows(), m = obstacle.vertices.rows();
    x.resize(n + m, 3);
    x.topRows(n) = cloth;
    x.bottomRows(m) = obstacle.vertices;
    v.setZero(n + m, 3);
    v.bottomRows(m).rowwise() = velocity.transpose();
    inverse_mass.setZero(n + m);
    inverse_mass.head(n).setOnes();
    motion.push_back({Mat3::Zero(), velocity});  // a translation: A = 0, c = its velocity
  }
};

// whether, at some of 1,000 instants of x + s dt v, an obstacle's corner is across the cloth
// triangle 0 1 2 from where it started, inside the triangle's extent (its projection inside)
bool corner_crosses(const Points& x, const Points& v, double dt, int first_corner) {
  const auto at = [&](double s, int k) { return Vec3(x.row(k) + s * dt * v.row(k)); };
  for (int k = first_corner; k < x.rows(); ++k) {
    const double before = side(at(0.0, k), at(0.0, 0), at(0.0, 1), at(0.0, 2));
    for (int i = 1; i <= 1000; ++i) {
      const double s = i / 1000.0;
      const Vec3 a = at(s, 0), b = at(s, 1), c = at(s, 2), p = at(s, k);
      const Vec3 n = (b - a).cross(c - a);
      // inside the extent: p's projection on the same side of each edge as the triangle
      const bool inside = n.dot((b - a).cross(p - a)) >= 0 && n.dot((c - b).cross(p - b)) >= 0 &&
                          n.dot((a - c).cross(p - c)) >= 0;
      if (inside && before * side(p, a, b, c) < 0.0) return true;
    }
  }
  return false;
}

}  // namespace

TEST(SelfCollision, AMovingObstacleCarriesTheClothItMeets) {
  // a horizontal obstacle triangle 0.1 m above a cloth triangle, wider than it, moving down
  // 0.3 m in the step: it must carry the cloth down with it. Of infinite mass, its velocity
  // stays; the cloth's vertices take its normal velocity, -30 m/s (and the collision's
  // separating speed, 1e-3 h / dt = 5e-4 m/s); no slip, no friction
  Points cloth(3, 3);
  cloth << 0, 0, 0, 0, 0, 1, 1, 0, 0;
  TriangleMesh lid;
  lid.vertices.resize(3, 3);
  lid.vertices << -1, 0.1, -1, -1, 0.1, 3, 3, 0.1, -1;
  lid.triangles.resize(1, 3);
  lid.triangles << 0, 1, 2;
  ClothAndObstacle s(cloth, lid, Vec3(0.0, -30.0, 0.0));
  Triangles t(1, 3);
  t << 0, 1, 2;
  SelfCollision self(t, 3, {lid});
  EXPECT_EQ(self.vertex_count(), 6);
  SelfCollisionSettings settings{0.005, 0.3};
  settings.obstacle_motion = &s.motion;
  SelfCollisionStatistics stats;
  const double dt = 0.01;
  const Points lid_velocity = s.v.bottomRows(3);
  self.resolve(s.x, s.v, s.inverse_mass, dt, settings, stats);
  EXPECT_GT(stats.collisions, 0);
  EXPECT_EQ(s.v.bottomRows(3), lid_velocity);  // the obstacle moves as it must
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(s.v(k, 1), -30.0, 1e-2) << k;
    EXPECT_LE(s.v(k, 1), -30.0) << k;
    EXPECT_NEAR(s.v(k, 0), 0.0, 1e-12) << k;
    EXPECT_NEAR(s.v(k, 2), 0.0, 1e-12) << k;
  }
  EXPECT_EQ(stats.repulsions, 0);  // the bodies' contacts hold the cloth off obstacles, not repulsions
}

TEST(SelfCollision, AnObstacleCornerDoesNotPokeThroughTheCloth) {
  // a 0.2 m box whose top is 5 cm under a cloth triangle (2 m across, its vertices far
  // outside the box), rising 0.3 m in the step: its four top corners would pierce the
  // triangle's inside, where no vertex or edge of the cloth is near them. Checked at 1,000
  // instants of the step by a side test written apart from the solver: no corner passes
  // the triangle; the box keeps its velocity; without the box as an obstacle, every top
  // corner passes it
  Points cloth(3, 3);
  cloth << -1, 0, -1, -1, 0, 2, 2, 0, -1;
  TriangleMesh box = make_box_mesh(Vec3::Constant(0.2), 1);
  box.vertices.col(1).array() -= 0.15;  // its top at y = -0.05
  Triangles t(1, 3);
  t << 0, 1, 2;
  const double dt = 0.01;
  SelfCollisionStatistics stats;
  {
    ClothAndObstacle s(cloth, box, Vec3(0.0, 30.0, 0.0));
    EXPECT_TRUE(corner_crosses(s.x, s.v, dt, 3));  // the case is what it says
    SelfCollision self(t, 3, {box});
    SelfCollisionSettings settings{0.005, 0.3};
    settings.obstacle_motion = &s.motion;
    const Points box_velocity = s.v.bottomRows(8);
    self.resolve(s.x, s.v, s.inverse_mass, dt, settings, stats);
    EXPECT_FALSE(corner_crosses(s.x, s.v, dt, 3));
    EXPECT_EQ(s.v.bottomRows(8), box_velocity);
    EXPECT_GT(stats.collisions, 0);
  }
  {
    // the same without obstacle motions (an impact zone holding the box would then hold
    // still): the collision impulses alone part them, the triangle being free to rise
    ClothAndObstacle s(cloth, box, Vec3(0.0, 30.0, 0.0));
    SelfCollision self(t, 3, {box});
    self.resolve(s.x, s.v, s.inverse_mass, dt, SelfCollisionSettings{0.005, 0.3}, stats);
    EXPECT_FALSE(corner_crosses(s.x, s.v, dt, 3));
  }
}

TEST(SelfCollision, AnImpactZoneWithAnObstacleMovesWithIt) {
  // the box of the test above, rising 0.3 m and turning 0.3 rad about y in the step, with no
  // collision passes: what the continuous test finds goes straight to the impact zones. The
  // zone of the cloth triangle and the box's corners moves as the box's points do, each
  // cloth vertex at A x + c (ObstacleMotion), so nothing in it passes through the box
  Points cloth(3, 3);
  cloth << -1, 0, -1, -1, 0, 2, 2, 0, -1;
  TriangleMesh box = make_box_mesh(Vec3::Constant(0.2), 1);
  box.vertices.col(1).array() -= 0.15;
  Triangles t(1, 3);
  t << 0, 1, 2;
  const double dt = 0.01;
  const Mat3 turn = Eigen::AngleAxisd(0.3, Vec3::UnitY()).toRotationMatrix();
  const ObstacleMotion motion{(turn - Mat3::Identity()) / dt, Vec3(0.0, 30.0, 0.0)};
  ClothAndObstacle s(cloth, box, Vec3::Zero());
  s.motion = {motion};
  for (int k = 3; k < 11; ++k) s.v.row(k) = (motion.A * s.x.row(k).transpose() + motion.c).transpose();
  EXPECT_TRUE(corner_crosses(s.x, s.v, dt, 3));
  SelfCollision self(t, 3, {box});
  SelfCollisionSettings settings{0.005, 0.3};
  settings.collision_passes = 0;
  settings.obstacle_motion = &s.motion;
  SelfCollisionStatistics stats;
  self.resolve(s.x, s.v, s.inverse_mass, dt, settings, stats);
  EXPECT_GT(stats.zone_rounds, 0);
  EXPECT_EQ(stats.stills, 0);
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(self.zone_vertices()[k], 1) << k;
    const Vec3 expected = motion.A * s.x.row(k).transpose() + motion.c;
    EXPECT_NEAR((s.v.row(k).transpose() - expected).norm(), 0.0, 1e-9) << k;
  }
  EXPECT_FALSE(corner_crosses(s.x, s.v, dt, 3));
}

// ---- bounded work: every loop of a step that can grow has a budget and a fallback
// (SelfCollisionSettings; README "Bounded work")

namespace {

// the upper layer of a cloth folded 1 cm over itself falling at 1 m/s onto the lower one:
// the layers meet within a 10 ms step, so candidates, collisions and zones all have work
struct FallingFold {
  ClothDesc desc = folded_grid(21, 0.01);
  Points x = desc.rest;
  Points v = Points::Zero(desc.rest.rows(), 3);
  Eigen::VectorXd inverse_mass = Eigen::VectorXd::Ones(desc.rest.rows());
  int n = static_cast<int>(desc.rest.rows());
  FallingFold() {
    for (int k = 0; k < n; ++k) {
      if (x(k, 1) > 0.005) v(k, 1) = -1.0;
    }
  }
};

// the cloth triangle of AMovingObstacleCarriesTheClothItMeets at y = 0 and the horizontal
// obstacle triangle (the lid), wider than it, 0.1 m above it
struct LidOverTriangle {
  Points cloth = Points(3, 3);
  TriangleMesh lid;
  Triangles t = Triangles(1, 3);
  LidOverTriangle() {
    cloth << 0, 0, 0, 0, 0, 1, 1, 0, 0;
    lid.vertices.resize(3, 3);
    lid.vertices << -1, 0.1, -1, -1, 0.1, 3, 3, 0.1, -1;
    lid.triangles.resize(1, 3);
    lid.triangles << 0, 1, 2;
    t << 0, 1, 2;
  }
};

}  // namespace

TEST(SelfCollision, OverItsCandidateBudgetAStepStopsAndSaysSo) {
  // with the default budgets the step finds its candidates and resolves the fold; with 1
  // candidate pair a vertex allowed, the search stops past n pairs (well short of all of
  // them), the step is over budget, counted once, and its calls change nothing; the next
  // step (begin_step) with the default budget resolves the fold again
  const double dt = 0.01;
  const FallingFold fold;
  SelfCollisionSettings settings{0.005, 0.3};
  SelfCollisionStatistics full;
  {
    SelfCollision self(fold.desc.triangles, fold.n);
    Points v = fold.v;
    self.resolve(fold.x, v, fold.inverse_mass, dt, settings, full);
    EXPECT_FALSE(self.over_budget());
    EXPECT_EQ(full.over_budget, 0);
  }
  ASSERT_GT(full.candidate_peak, 4 * fold.n);  // the case is what it says
  SelfCollision self(fold.desc.triangles, fold.n);
  settings.candidate_budget = 1.0;
  settings.budget_vertices = 0;  // (else it counts a 64 x 64 cloth's)
  SelfCollisionStatistics stats;
  Points v = fold.v;
  self.begin_step();
  self.repel(fold.x, v, fold.inverse_mass, dt, settings, stats);
  EXPECT_TRUE(self.over_budget());
  EXPECT_FALSE(self.collide(fold.x, v, fold.inverse_mass, dt, settings, stats, 4));
  self.impact_zones(fold.x, v, fold.inverse_mass, dt, settings, stats);
  EXPECT_EQ(v, fold.v);  // nothing done: the caller holds the cloth still
  EXPECT_EQ(stats.over_budget, 1);
  EXPECT_EQ(stats.repulsions + stats.collisions + stats.zone_rounds, 0);
  EXPECT_GT(stats.candidate_peak, fold.n);
  EXPECT_LT(stats.candidate_peak, full.candidate_peak / 2);  // it stopped short, not after
  settings.candidate_budget = SelfCollisionSettings().candidate_budget;
  self.resolve(fold.x, v, fold.inverse_mass, dt, settings, stats);  // (begins a step)
  EXPECT_FALSE(self.over_budget());
  EXPECT_EQ(stats.over_budget, 1);
  EXPECT_GT(stats.collisions + stats.zone_rounds, 0);
  EXPECT_TRUE(intersecting_triangle_pairs(fold.x + dt * v, fold.desc.triangles).empty());
}

TEST(SelfCollision, OverItsPassBudgetAStepStopsAndSaysSo) {
  // the collision passes of a step may visit pass_budget pairs a vertex in all: at 1, the
  // first pass (visiting every candidate, more than n) would exceed it, so none runs
  const double dt = 0.01;
  const FallingFold fold;
  SelfCollisionSettings settings{0.005, 0.3};
  settings.pass_budget = 1.0;
  settings.budget_vertices = 0;
  SelfCollision self(fold.desc.triangles, fold.n);
  SelfCollisionStatistics stats;
  Points v = fold.v;
  self.begin_step();
  EXPECT_FALSE(self.collide(fold.x, v, fold.inverse_mass, dt, settings, stats, 4));
  EXPECT_TRUE(self.over_budget());
  EXPECT_EQ(stats.over_budget, 1);
  EXPECT_EQ(stats.collisions, 0);
  EXPECT_EQ(stats.pass_peak, 0);
  EXPECT_EQ(v, fold.v);
  // the default allows the whole of this step's passes, and records what they visited
  settings.pass_budget = SelfCollisionSettings().pass_budget;
  self.resolve(fold.x, v, fold.inverse_mass, dt, settings, stats);
  EXPECT_FALSE(self.over_budget());
  EXPECT_GT(stats.pass_peak, 0);
  EXPECT_LT(stats.pass_peak, settings.pass_budget * fold.n);
  EXPECT_LT(stats.candidate_peak, settings.candidate_budget * fold.n);
}

TEST(SelfCollision, ImpactZonesThatDoNotSettleHoldTheClothStill) {
  // the last resort of the zone rounds' budget (zone_iterations): with none allowed, the
  // point falling through a triangle is not resolved by zones, and the cloth holds still
  Points x(4, 3), v(4, 3);
  x << 0, 0, 0, 1, 0, 0, 0, 0, 1, 0.25, 0.1, 0.25;
  v.setZero();
  v.row(3) << 0.0, -30.0, 0.0;
  Triangles t(1, 3);
  t << 0, 2, 1;
  SelfCollision self(t, 4);
  SelfCollisionSettings settings{0.005, 0.0};
  settings.collision_passes = 0;
  settings.zone_iterations = 0;
  SelfCollisionStatistics stats;
  self.resolve(x, v, Eigen::VectorXd::Ones(4), 0.01, settings, stats);
  EXPECT_EQ(stats.stills, 1);
  EXPECT_EQ(v.norm(), 0.0);
  settings.zone_iterations = 50;  // one round is enough
  v.row(3) << 0.0, -30.0, 0.0;
  self.resolve(x, v, Eigen::VectorXd::Ones(4), 0.01, settings, stats);
  EXPECT_EQ(stats.stills, 1);
  EXPECT_EQ(stats.zone_round_peak, 1);
}

TEST(SelfCollision, AZoneAKeyedObstacleWouldPressIntoTheGroundHoldsStill) {
  // the lid of AMovingObstacleCarriesTheClothItMeets coming down at 30 m/s onto a cloth
  // triangle lying on the ground (its vertices' support: +y), straight to the impact zones:
  // the zone of the triangle and the lid cannot follow the lid into the ground; it holds
  // still and the lid passes through (yields). Off the ground it follows the lid
  const LidOverTriangle scene;
  const Points& cloth = scene.cloth;
  const TriangleMesh& lid = scene.lid;
  const Triangles& t = scene.t;
  for (const bool on_ground : {false, true}) {
    ClothAndObstacle s(cloth, lid, Vec3(0.0, -30.0, 0.0));
    std::vector<Vec3> support(6, Vec3::Zero());
    if (on_ground) support[0] = support[1] = support[2] = Vec3(0.0, 1.0, 0.0);
    SelfCollision self(t, 3, {lid});
    SelfCollisionSettings settings{0.005, 0.3};
    settings.collision_passes = 0;
    settings.obstacle_motion = &s.motion;
    settings.support = &support;
    SelfCollisionStatistics stats;
    self.resolve(s.x, s.v, s.inverse_mass, 0.01, settings, stats);
    EXPECT_GT(stats.zone_rounds, 0);
    EXPECT_EQ(stats.stills, 0);
    EXPECT_EQ(stats.yields, on_ground ? 1 : 0);
    for (int k = 0; k < 3; ++k) EXPECT_EQ(s.v(k, 1), on_ground ? 0.0 : -30.0) << k << " " << on_ground;
  }
}

TEST(SelfCollision, AnObstacleNoLongerKeepsOutTheVerticesLetIn) {
  // the same lid onto the same triangle in the air: the lid carries it down, unless the
  // triangle's vertices are let in (SelfCollisionSettings::yielding): then nothing is
  // tested between them and the lid, which passes through
  const LidOverTriangle scene;
  const Points& cloth = scene.cloth;
  const TriangleMesh& lid = scene.lid;
  const Triangles& t = scene.t;
  for (const bool let_in : {false, true}) {
    ClothAndObstacle s(cloth, lid, Vec3(0.0, -30.0, 0.0));
    const std::vector<char> yielding = {1, 1, 1, 0, 0, 0};
    SelfCollision self(t, 3, {lid});
    SelfCollisionSettings settings{0.005, 0.3};
    settings.obstacle_motion = &s.motion;
    if (let_in) settings.yielding = &yielding;
    SelfCollisionStatistics stats;
    self.resolve(s.x, s.v, s.inverse_mass, 0.01, settings, stats);
    EXPECT_EQ(stats.collisions == 0, let_in);
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(s.v(k, 1), let_in ? 0.0 : -30.0, 1e-2) << k;
  }
}
