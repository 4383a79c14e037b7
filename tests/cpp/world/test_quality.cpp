// The quality figures (world/quality.h, geometry/triangle_intersection.h) against
// configurations with known answers.
#include <gtest/gtest.h>

#include "geometry/triangle_intersection.h"
#include "levelset/vdb_levelset.h"
#include "test_support.h"
#include "world/quality.h"

#include <cstring>
#include <random>

using namespace simbake;
using namespace simbake::test;

namespace {

// All crossing pairs by testing every pair: the reference for the grid's candidate search
std::vector<std::pair<int, int>> brute_force_pairs(const Points& x, const Triangles& t) {
  std::vector<std::pair<int, int>> pairs;
  for (int i = 0; i < t.rows(); ++i) {
    for (int j = i + 1; j < t.rows(); ++j) {
      bool shared = false;
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) shared = shared || t(i, a) == t(j, b);
      if (shared) continue;
      if (triangles_intersect(x.row(t(i, 0)), x.row(t(i, 1)), x.row(t(i, 2)), x.row(t(j, 0)), x.row(t(j, 1)),
                              x.row(t(j, 2)))) {
        pairs.emplace_back(i, j);
      }
    }
  }
  return pairs;
}

}  // namespace

TEST(TriangleIntersection, KnownConfigurations) {
  const Vec3 a0(0, 0, 0), a1(1, 0, 0), a2(0, 0, 1);
  // a vertical triangle piercing the flat one through its middle
  EXPECT_TRUE(triangles_intersect(a0, a1, a2, Vec3(0.2, -1, 0.2), Vec3(0.2, 1, 0.2), Vec3(0.3, 1, 0.3)));
  // the same, moved beyond the flat triangle's hypotenuse: it crosses the plane only
  EXPECT_FALSE(triangles_intersect(a0, a1, a2, Vec3(0.8, -1, 0.8), Vec3(0.8, 1, 0.8), Vec3(0.9, 1, 0.9)));
  // parallel, 1 mm apart
  EXPECT_FALSE(triangles_intersect(a0, a1, a2, a0 + Vec3(0, 1e-3, 0), a1 + Vec3(0, 1e-3, 0), a2 + Vec3(0, 1e-3, 0)));
  // crossing like two links of a chain: neither has a vertex inside the other, edges pierce
  EXPECT_TRUE(triangles_intersect(Vec3(-1, 0, -1), Vec3(1, 0, -1), Vec3(0, 0, 1), Vec3(0, -1, 0), Vec3(0, 1, 0),
                                  Vec3(0, 0.5, -3)));
  // symmetric in its arguments
  EXPECT_TRUE(triangles_intersect(Vec3(0.2, -1, 0.2), Vec3(0.2, 1, 0.2), Vec3(0.3, 1, 0.3), a0, a1, a2));
}

TEST(TriangleIntersection, FlatAndDrapedGridsHaveNone) {
  ClothDesc grid = grid_cloth(33, 33, 2.0, 2.0);
  EXPECT_TRUE(intersecting_triangle_pairs(grid.rest, grid.triangles).empty());
  // a smooth wave: adjacent triangles meet at angles, none crosses
  for (Eigen::Index k = 0; k < grid.rest.rows(); ++k) grid.rest(k, 1) = 0.3 * std::sin(4.0 * grid.rest(k, 0));
  EXPECT_TRUE(intersecting_triangle_pairs(grid.rest, grid.triangles).empty());
}

TEST(TriangleIntersection, GridSearchFindsWhatEveryPairFinds) {
  // a grid crumpled at random (heights of two cell sizes) and with a fold of its far half
  // back under the near half: the grid search must find exactly the all-pairs test's pairs
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> crumple(-0.1, 0.1), jitter(-0.01, 0.01);
  ClothDesc grid = grid_cloth(21, 21, 1.0, 1.0);
  for (Eigen::Index k = 0; k < grid.rest.rows(); ++k) {
    const double z = grid.rest(k, 2);
    if (z > 0.5) grid.rest.row(k) << grid.rest(k, 0), 0.0, 1.0 - z;
    grid.rest(k, 0) += jitter(rng);
    grid.rest(k, 1) += crumple(rng);
    grid.rest(k, 2) += jitter(rng);
  }
  const auto reference = brute_force_pairs(grid.rest, grid.triangles);
  const auto found = intersecting_triangle_pairs(grid.rest, grid.triangles);
  EXPECT_GT(reference.size(), 100u);
  EXPECT_EQ(found, reference);
}

TEST(TriangleIntersection, CountsACrossOfTwoStrips) {
  // two one-cell strips crossing at right angles, each of two triangles: the vertical
  // strip's near triangle crosses both of the flat one's (its diagonal runs under it), and
  // the flat strip's edges pierce the vertical strip's triangles: 4 pairs at most
  Points x(8, 3);
  x << -1, 0, -0.2, 1, 0, -0.2, 1, 0, 0.2, -1, 0, 0.2,  // flat strip along x
      -0.1, -1, 0, 0.1, -1, 0, 0.1, 1, 0, -0.1, 1, 0;  // vertical strip in the z = 0 plane
  Triangles t(4, 3);
  t << 0, 1, 2, 0, 2, 3, 4, 5, 6, 4, 6, 7;
  const auto pairs = intersecting_triangle_pairs(x, t);
  EXPECT_EQ(pairs, brute_force_pairs(x, t));
  EXPECT_FALSE(pairs.empty());
  for (const auto& [i, j] : pairs) EXPECT_TRUE(i < 2 && j >= 2);
}

TEST(TriangleIntersection, WorkBudgetIsCheckedBeforeAnyTest) {
  // 3,000 random triangles across a unit cube: about 4.5e6 candidate pairs in a few cells;
  // a budget below that is refused, one above answers as the unbounded search does
  std::mt19937 rng(30);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  Points x(9000, 3);
  for (Eigen::Index k = 0; k < x.rows(); ++k) x.row(k) << unit(rng), unit(rng), unit(rng);
  Triangles t(3000, 3);
  for (Eigen::Index k = 0; k < t.rows(); ++k) t.row(k) << 3 * k, 3 * k + 1, 3 * k + 2;
  EXPECT_THROW(intersecting_triangle_pairs(x, t, 1'000'000), std::length_error);
  EXPECT_EQ(intersecting_triangle_pairs(x, t, 100'000'000), intersecting_triangle_pairs(x, t));
}

TEST(Quality, BoxPushedOneCentimetreIntoAnother) {
  World world;
  world.set_ground(GroundDef{});
  world.add_body(box_body(Vec3(1, 1, 1), 1.0, Vec3(0, 0.5, 0)));
  world.add_body(box_body(Vec3(1, 1, 1), 1.0, Vec3(0.3, 1.49, 0.1)));
  const PenetrationFigure p = body_penetration(world);
  EXPECT_NEAR(p.depth, 0.01, 1e-12);
  EXPECT_EQ(std::min(p.a, p.b), 0);
  EXPECT_EQ(std::max(p.a, p.b), 1);
}

TEST(Quality, BoxSunkIntoTheGroundAndKinematicPairsIgnored) {
  World world;
  world.set_ground(GroundDef{0.0, 0.5, 0.0});
  world.add_body(box_body(Vec3(1, 1, 1), 1.0, Vec3(5, 0.497, 0)));
  BodyDesc wall = box_body(Vec3(1, 1, 1), 1.0, Vec3(0, 0.0, 0));  // half in the ground, kinematic
  wall.kinematic = true;
  world.add_body(wall);
  BodyDesc other = wall;  // overlapping the first kinematic one by half: not the solver's doing
  other.origin = Vec3(0.5, 0.0, 0);
  world.add_body(other);
  const PenetrationFigure p = body_penetration(world);
  EXPECT_NEAR(p.depth, 0.003, 1e-12);
  EXPECT_EQ(p.a, 0);
  EXPECT_EQ(p.b, -1);
}

TEST(Quality, PrunedFigureIsEverySamplesFigureBitForBit) {
  // boxes (some with a sample pushed off the box), spheres and kinematic boxes thrown into
  // one another and the ground at random, then stepped: the figure that skips what its
  // bounds rule out is the figure that tests every sample, depth and names, at every frame
  for (int seed = 0; seed < 6; ++seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    World world;
    world.set_ground(GroundDef{});
    for (int k = 0; k < 60; ++k) {
      const Vec3 origin(1.6 * unit(rng), 0.1 + 1.2 * unit(rng), 1.6 * unit(rng));
      BodyDesc d = k % 3 == 2 ? sphere_body(0.1 + 0.2 * unit(rng), 1.0, origin, 3)
                              : box_body(Vec3(0.2 + 0.4 * unit(rng), 0.2 + 0.3 * unit(rng), 0.3), 1.0, origin, 2);
      d.orientation = Quat(unit(rng) - 0.5, unit(rng) - 0.5, unit(rng) - 0.5, unit(rng) - 0.5).normalized();
      if (k % 11 == 3) d.samples(0, 0) *= 1.01;  // a sample just off its box
      d.kinematic = k % 13 == 5;
      world.add_body(d);
    }
    QualityMeter meter;
    for (int frame = 0; frame < 12; ++frame) {
      const PenetrationFigure every = body_penetration_every_sample(world);
      const PenetrationFigure pruned = body_penetration(world);
      const PenetrationFigure kept = meter.measure(world).body_penetration;
      if (frame == 0) EXPECT_GT(every.depth, 0.0);
      for (const PenetrationFigure& p : {pruned, kept}) {
        EXPECT_EQ(std::memcmp(&p.depth, &every.depth, sizeof p.depth), 0) << "seed " << seed << " frame " << frame;
        EXPECT_EQ(p.a, every.a);
        EXPECT_EQ(p.b, every.b);
      }
      world.step_frame(1.0 / 24.0, 2);
    }
  }
}

TEST(Quality, GridOfPairsIsTheSweepsBitForBit) {
  // a tilted grid of boxes falling onto a wide kinematic slab and onto one another (the pairs
  // come from the grid of cubes, the slab against every body): the same figure as the sweep's
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  World world;
  world.set_ground(GroundDef{});
  BodyDesc slab = box_body(Vec3(8, 0.2, 8), 1.0, Vec3(0, 0.1, 0));
  slab.kinematic = true;
  world.add_body(slab);
  for (int i = 0; i < 6; ++i)
    for (int j = 0; j < 4; ++j)
      for (int k = 0; k < 6; ++k) {
        BodyDesc d = box_body(Vec3(0.5, 0.5, 0.5), 1.0, Vec3(0.52 * i - 1.5, 0.3 + 0.52 * j, 0.52 * k - 1.5), 2);
        d.orientation = Quat(1.0, 0.1 * unit(rng), 0.1 * unit(rng), 0.1 * unit(rng)).normalized();
        world.add_body(d);
      }
  for (int frame = 0; frame < 24; ++frame) {
    const PenetrationFigure every = body_penetration_every_sample(world);
    const PenetrationFigure pruned = body_penetration(world);
    EXPECT_EQ(std::memcmp(&pruned.depth, &every.depth, sizeof every.depth), 0) << "frame " << frame;
    EXPECT_EQ(pruned.a, every.a);
    EXPECT_EQ(pruned.b, every.b);
    world.step_frame(1.0 / 24.0, 4);
  }
}

TEST(Quality, NoBodyOrOneBodyHasNoPair) {
  World world;
  QualityMeter meter;
  EXPECT_EQ(meter.measure(world).body_penetration.a, -1);
  world.set_ground(GroundDef{});
  world.add_body(box_body(Vec3(1, 1, 1), 1.0, Vec3(0, 0.49, 0)));
  EXPECT_NEAR(meter.measure(world).body_penetration.depth, 0.01, 1e-12);
  EXPECT_NEAR(body_penetration(world).depth, 0.01, 1e-12);
}

TEST(Quality, MeterKeepsTheFigureOnlyWhileNothingMoves) {
  World world;
  world.set_ground(GroundDef{});
  world.add_body(box_body(Vec3(1, 1, 1), 1.0, Vec3(0, 0.5, 0)));
  const int top = world.add_body(box_body(Vec3(1, 1, 1), 1.0, Vec3(0.3, 1.49, 0.1)));
  QualityMeter meter;
  EXPECT_NEAR(meter.measure(world).body_penetration.depth, 0.01, 1e-12);
  EXPECT_NEAR(meter.measure(world).body_penetration.depth, 0.01, 1e-12);
  world.rigid_data().x[top].y() -= 0.01;  // pushed 1 cm further in
  EXPECT_NEAR(meter.measure(world).body_penetration.depth, 0.02, 1e-12);
}

TEST(Quality, MeterTakesTheDepthsOfPairsThatDidNotMoveFromBefore) {
  // still pairs 4 mm and 6 mm into each other, and a box pushed into another a little
  // further each frame, then pulled out, then a still box nudged: at every frame the
  // meter's figure (still pairs' depths from memory) is every sample's, depth and names
  World world;
  world.set_ground(GroundDef{});
  world.add_body(box_body(Vec3(1, 1, 1), 1.0, Vec3(0, 0.5, 0)));
  world.add_body(box_body(Vec3(1, 1, 1), 1.0, Vec3(0.996, 0.5, 0)));  // 4 mm into body 0
  world.add_body(box_body(Vec3(1, 1, 1), 1.0, Vec3(4, 0.5, 0)));
  const int nudged = world.add_body(box_body(Vec3(1, 1, 1), 1.0, Vec3(4, 1.494, 0)));  // 6 mm into body 2
  world.add_body(box_body(Vec3(1, 1, 1), 1.0, Vec3(8, 0.5, 0)));
  const int ball = world.add_body(box_body(Vec3(1, 1, 1), 1.0, Vec3(8.2, 1.5, 0.1)));
  QualityMeter meter;
  const double pushes[] = {0.0, 0.002, 0.005, 0.009, 0.009, 0.003, 0.0, 0.0};
  for (int frame = 0; frame < 10; ++frame) {
    if (frame < 8) world.rigid_data().x[ball].y() = 1.5 - pushes[frame];
    if (frame == 8) world.rigid_data().x[nudged].y() -= 0.005;  // 11 mm in
    const PenetrationFigure every = body_penetration_every_sample(world);
    const PenetrationFigure kept = meter.measure(world).body_penetration;
    EXPECT_EQ(std::memcmp(&kept.depth, &every.depth, sizeof kept.depth), 0) << "frame " << frame;
    EXPECT_EQ(kept.a, every.a) << "frame " << frame;
    EXPECT_EQ(kept.b, every.b) << "frame " << frame;
    if (frame == 0 || frame == 6) EXPECT_NEAR(every.depth, 0.006, 1e-9);
    if (frame == 3) EXPECT_NEAR(every.depth, 0.009, 1e-9);
    if (frame >= 8) EXPECT_NEAR(every.depth, 0.011, 1e-9);
  }
}

TEST(Quality, MeterOnGridShapesIsEverySamplesFigureFrameAfterFrame) {
  // baked boxes and spheres (grids: the meter bounds a pair by its depth before and how far
  // its samples moved through the other's field) dropped in a heap onto the ground and one
  // another and left to settle: at every frame the meter's figure is every sample's
  const TriangleMesh box = make_box_mesh(Vec3(0.4, 0.3, 0.5), 2);
  const TriangleMesh ball = make_sphere_mesh(0.25, 3);
  const auto box_grid = VdbLevelSet::bake(box.vertices, box.triangles, 0.04);
  const auto ball_grid = VdbLevelSet::bake(ball.vertices, ball.triangles, 0.04);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  World world;
  world.set_ground(GroundDef{});
  for (int k = 0; k < 24; ++k) {
    const Vec3 origin(1.2 * unit(rng), 0.3 + 0.4 * k / 3, 1.2 * unit(rng));
    BodyDesc d = k % 2 ? sphere_body(0.25, 1.0, origin, 3) : box_body(Vec3(0.4, 0.3, 0.5), 1.0, origin, 2);
    d.shape = k % 2 ? SignedDistancePtr(ball_grid) : SignedDistancePtr(box_grid);
    d.orientation = Quat(unit(rng) - 0.5, unit(rng) - 0.5, unit(rng) - 0.5, unit(rng) - 0.5).normalized();
    world.add_body(d);
  }
  QualityMeter meter;
  double deepest = 0.0;
  for (int frame = 0; frame < 48; ++frame) {
    const PenetrationFigure every = body_penetration_every_sample(world);
    const PenetrationFigure kept = meter.measure(world).body_penetration;
    EXPECT_EQ(std::memcmp(&kept.depth, &every.depth, sizeof kept.depth), 0) << "frame " << frame;
    EXPECT_EQ(kept.a, every.a) << "frame " << frame;
    EXPECT_EQ(kept.b, every.b) << "frame " << frame;
    deepest = std::max(deepest, every.depth);
    world.step_frame(1.0 / 24.0, 2);
  }
  EXPECT_GT(deepest, 0.0);  // (something was inside something)
}

TEST(Quality, ClothEdgeThroughASphereBetweenVerticesOutside) {
  // one triangle whose edge from (-1, 0.4, 0) to (1, 0.4, 0) passes 0.4 m from the centre of
  // a 0.5 m sphere: its vertices are outside, its midpoint 0.1 m inside
  World world;
  world.add_body(sphere_body(0.5, 1.0, Vec3::Zero()));
  ClothDesc d;
  d.rest.resize(3, 3);
  d.rest << -1, 0.4, 0, 1, 0.4, 0, 0, 0.4, 2;
  d.triangles.resize(1, 3);
  d.triangles << 0, 1, 2;
  world.add_cloth(test::with_contacts(d, 0.3, 0.005));
  const ClothQuality q = cloth_quality(world, 0);
  EXPECT_EQ(q.vertex_penetration.depth, 0.0);
  EXPECT_EQ(q.vertex_penetration.a, -1);
  EXPECT_NEAR(q.edge_penetration.depth, 0.1, 1e-12);
  EXPECT_EQ(q.edge_penetration.a, 0);
  EXPECT_EQ(q.edge_penetration.b, 0);
  EXPECT_NEAR(q.max_strain, 0.0, 1e-15);
  EXPECT_EQ(q.self_intersections, 0);
}
