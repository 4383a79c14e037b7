// The world step against analytic answers: free fall, bounces, sliding and sticking on a
// tilted ground, resting without sinking or jitter, kinematic bodies, determinism.
#include <gtest/gtest.h>

#include <set>
#include <string>

#include "test_support.h"

#include <vector>

using namespace simbake;
using namespace simbake::test;

namespace {

// Apex heights (of the lowest point above the ground) of a bouncing sphere
std::vector<double> bounce_apexes(double drop_height, double restitution, int substeps, int count) {
  WorldSettings settings;
  World world(settings);
  world.set_ground(GroundDef{0.0, 0.0, 0.0});
  BodyDesc ball = sphere_body(0.1, 1.0, Vec3(0.0, drop_height + 0.1, 0.0));
  ball.restitution = restitution;
  ball.friction = 0.0;
  world.add_body(ball);
  std::vector<double> apexes;
  double previous_vy = 0.0;
  for (int frame = 0; frame < 24 * 10 && int(apexes.size()) < count; ++frame) {
    for (int k = 0; k < substeps; ++k) {
      world.step(1.0 / 24.0 / substeps);
      const RigidBodyState& s = world.body_state(0);
      if (previous_vy > 0.0 && s.v.y() <= 0.0) apexes.push_back(s.x.y() - 0.1);
      previous_vy = s.v.y();
    }
  }
  return apexes;
}

// Box of 0.5 m on a ground under gravity tilted by `angle` about z; returns the distance
// slid along -x (downhill) after `seconds`, and the tipping of the box (rad)
struct Slide { double distance, velocity, tilt; };
Slide slide_box(double angle, double friction, double seconds, const Vec3& v0 = Vec3::Zero(),
                int samples_per_edge = 4) {
  WorldSettings settings;
  const double g = 9.81;
  settings.gravity = Vec3(-g * std::sin(angle), -g * std::cos(angle), 0.0);
  World world(settings);
  world.set_ground(GroundDef{0.0, friction, 0.0});
  BodyDesc box = box_body(Vec3::Constant(0.5), 10.0, Vec3(0.0, 0.25, 0.0), samples_per_edge);
  box.friction = friction;
  box.linear_velocity = v0;
  world.add_body(box);
  const int frames = static_cast<int>(std::lround(seconds * 24.0));
  for (int f = 0; f < frames; ++f) world.step_frame(1.0 / 24.0);
  const RigidBodyState& s = world.body_state(0);
  const double tilt = std::acos(std::min(1.0, std::abs((s.q * Vec3::UnitY()).y())));
  return {-s.x.x(), -s.v.x(), tilt};
}

}  // namespace

TEST(World, FreeFallMatchesParabolaToFirstOrder) {
  World world;
  world.add_body(sphere_body(0.5, 2.0, Vec3(0.0, 10.0, 0.0)));
  const double dt = 1.0 / 240.0, t = 1.0;
  for (int k = 0; k < 240; ++k) world.step(dt);
  // symplectic Euler: y_n = y0 - g t^2 / 2 - g t dt / 2 exactly
  EXPECT_NEAR(world.body_state(0).x.y(), 10.0 - 0.5 * 9.81 * t * t - 0.5 * 9.81 * t * dt, 1e-9);
  EXPECT_NEAR(world.body_state(0).v.y(), -9.81 * t, 1e-9);
}

// A ball dropped from h with restitution e reaches e^(2k) h after the k-th bounce
TEST(World, BounceApexesFollowRestitutionSquared) {
  const double h = 1.0, e = 0.5;
  const std::vector<double> apexes = bounce_apexes(h, e, 20, 3);  // dt = 1/480 s
  ASSERT_EQ(apexes.size(), 3u);
  for (int k = 0; k < 3; ++k) {
    const double expected = std::pow(e, 2 * (k + 1)) * h;
    // the impulse is applied up to one step (|v| dt, 9 mm at impact) before contact, which
    // shifts each apex by a few percent of the smallest one at this step
    EXPECT_NEAR(apexes[k] / expected, 1.0, 0.04) << "bounce " << k + 1;
  }
}

TEST(World, BounceErrorShrinksWithTheStep) {
  const double expected = 0.25;
  const double coarse = std::abs(bounce_apexes(1.0, 0.5, 4, 1).at(0) - expected);
  const double fine = std::abs(bounce_apexes(1.0, 0.5, 32, 1).at(0) - expected);
  EXPECT_LT(fine, 0.5 * coarse);
}

// Sliding under tilted gravity: a = g (sin a - mu cos a), from rest: d = a t^2 / 2
TEST(World, BoxSlidesAtTheCoulombRate) {
  const double angle = 30.0 * M_PI / 180.0, mu = 0.3, t = 2.0;
  const double a = 9.81 * (std::sin(angle) - mu * std::cos(angle));
  const Slide slide = slide_box(angle, mu, t);
  EXPECT_NEAR(slide.velocity / (a * t), 1.0, 0.02);
  EXPECT_NEAR(slide.distance / (0.5 * a * t * t), 1.0, 0.03);
  EXPECT_LT(slide.tilt, 0.01);  // slides flat, does not tip or rock
}

// with corners only and with samples on the edges and faces as the pipeline places them
TEST(World, BoxSticksWhenFrictionExceedsTheSlope) {
  const double angle = 30.0 * M_PI / 180.0;  // tan = 0.577
  for (int samples_per_edge : {1, 2, 4}) {
    const Slide slide = slide_box(angle, 0.7, 3.0, Vec3::Zero(), samples_per_edge);
    EXPECT_LT(std::abs(slide.distance), 1e-4) << samples_per_edge;
    EXPECT_LT(std::abs(slide.velocity), 1e-4) << samples_per_edge;
    EXPECT_LT(slide.tilt, 1e-3) << samples_per_edge;
  }
}

TEST(World, MovingBoxStopsWhereFrictionSaysOnFlatGround) {
  // v0 = 2 m/s, mu = 0.5: stops after v0^2 / (2 mu g) = 0.408 m
  const Slide slide = slide_box(0.0, 0.5, 2.0, Vec3(-2.0, 0.0, 0.0));
  EXPECT_NEAR(slide.distance, 4.0 / (2.0 * 0.5 * 9.81), 0.02);
  EXPECT_NEAR(slide.velocity, 0.0, 1e-6);
}

TEST(World, RestingBoxNeitherSinksNorJitters) {
  World world;
  world.set_ground(GroundDef{0.0, 0.5, 0.0});
  world.add_body(box_body(Vec3(1.0, 0.5, 0.8), 50.0, Vec3(0.0, 0.25, 0.0)));
  double lowest = 1.0, highest = 0.0, fastest = 0.0;
  for (int f = 0; f < 24 * 5; ++f) {
    world.step_frame(1.0 / 24.0);
    const RigidBodyState& s = world.body_state(0);
    lowest = std::min(lowest, s.x.y());
    highest = std::max(highest, s.x.y());
    fastest = std::max(fastest, s.v.norm() + angular_velocity(world.body_def(0), s).norm());
  }
  EXPECT_GT(lowest, 0.25 - 1e-4);
  EXPECT_LT(highest, 0.25 + 1e-4);
  EXPECT_LT(fastest, 1e-2);
  EXPECT_LT(world.statistics().max_penetration, 1e-4);
}

TEST(World, SphereComesToRestOnAKinematicBox) {
  World world;
  BodyDesc table = box_body(Vec3(2.0, 0.2, 2.0), 1.0, Vec3(0.0, 0.5, 0.0));
  table.kinematic = true;
  world.add_body(table);
  world.add_body(sphere_body(0.2, 1.0, Vec3(0.1, 1.5, 0.0), 12));
  for (int f = 0; f < 24 * 3; ++f) world.step_frame(1.0 / 24.0);
  const RigidBodyState& ball = world.body_state(1);
  EXPECT_NEAR(ball.x.y(), 0.6 + 0.2, 2e-3);  // on the top face
  EXPECT_LT(ball.v.norm(), 1e-2);
  EXPECT_TRUE(world.body_state(0).x.isApprox(Vec3(0.0, 0.5, 0.0)));  // never moved
}

TEST(World, KinematicBodyMovesWithItsVelocity) {
  World world;
  BodyDesc mover = box_body(Vec3::Ones(), 1.0, Vec3::Zero());
  mover.kinematic = true;
  mover.linear_velocity = Vec3(1.0, 0.0, 0.0);
  mover.angular_velocity = Vec3(0.0, M_PI, 0.0);
  world.add_body(mover);
  world.step_frame(0.5, 3);
  EXPECT_TRUE(world.body_state(0).x.isApprox(Vec3(0.5, 0.0, 0.0), 1e-12));
  // half a turn per half second about y
  const Vec3 x_axis = world.body_mesh_pose(0).rotation * Vec3::UnitX();
  EXPECT_NEAR(x_axis.x(), 0.0, 1e-9);
  EXPECT_NEAR(x_axis.z(), -1.0, 1e-9);
}

TEST(World, AutomaticSubstepsFollowSpeed) {
  World world;
  world.add_body(sphere_body(0.1, 1.0, Vec3::Zero()));
  const int resting = world.automatic_substeps(1.0 / 24.0);
  world.rigid_data().v[0] = Vec3(100.0, 0.0, 0.0);
  const int fast = world.automatic_substeps(1.0 / 24.0);
  EXPECT_EQ(resting, 5);  // the 1/120 s ceiling
  // 100 m/s over 1/24 s is 4.17 m; 0.2 of the 0.2 m thickness per substep -> 105 substeps
  EXPECT_GE(fast, 104);
  EXPECT_LE(fast, 106);
}

TEST(World, SameInputSameOutput) {
  auto run = [] {
    World world;
    world.set_ground(GroundDef{0.0, 0.4, 0.2});
    BodyDesc box = box_body(Vec3(0.4, 0.3, 0.2), 3.0, Vec3(0.0, 1.0, 0.0));
    box.orientation = Quat(Eigen::AngleAxisd(0.5, Vec3(1, 2, 3).normalized()));
    box.angular_velocity = Vec3(3.0, -2.0, 1.0);
    world.add_body(box);
    world.add_body(sphere_body(0.2, 1.0, Vec3(0.1, 2.0, 0.0)));
    for (int f = 0; f < 48; ++f) world.step_frame(1.0 / 24.0);
    return std::make_pair(world.body_state(0).x, world.body_state(1).q.coeffs());
  };
  const auto a = run(), b = run();
  EXPECT_EQ(a.first, b.first);
  EXPECT_EQ(a.second, b.second);
}

TEST(World, RejectsBadBodies) {
  World world;
  BodyDesc bad = sphere_body(0.1, -1.0, Vec3::Zero());
  EXPECT_THROW(world.add_body(bad), std::invalid_argument);
  bad = sphere_body(0.1, 1.0, Vec3(NAN, 0.0, 0.0));
  EXPECT_THROW(world.add_body(bad), std::invalid_argument);
  bad = sphere_body(0.1, 1.0, Vec3::Zero());
  bad.restitution = 1.5;
  EXPECT_THROW(world.add_body(bad), std::invalid_argument);
}

// A keyed kinematic platform follows its keys exactly (linear between keys, slerp in
// orientation, held after the last key)
TEST(World, KeyedKinematicBodyFollowsItsKeys) {
  World world;
  BodyDesc platform = box_body(Vec3(2.0, 0.2, 2.0), 1.0, Vec3::Zero(), 3);
  platform.kinematic = true;
  const int p = world.add_body(platform);
  const Quat turned(Eigen::AngleAxisd(M_PI / 2.0, Vec3::UnitY()));
  world.set_kinematic_track(p, KinematicTrack({0.5, 2.5}, {Vec3(0.0, 0.0, 0.0), Vec3(2.0, 0.0, 0.0)},
                                              {Quat::Identity(), turned}));
  for (int f = 0; f < 36; ++f) world.step_frame(1.0 / 24.0);  // t = 1.5 s: half way along
  EXPECT_TRUE(world.body_mesh_pose(p).translation.isApprox(Vec3(1.0, 0.0, 0.0), 1e-9));
  const Quat half(Eigen::AngleAxisd(M_PI / 4.0, Vec3::UnitY()));
  EXPECT_TRUE(Quat(world.body_mesh_pose(p).rotation).isApprox(half, 1e-9));
  for (int f = 0; f < 36; ++f) world.step_frame(1.0 / 24.0);  // t = 3 s: held at the last key
  EXPECT_TRUE(world.body_mesh_pose(p).translation.isApprox(Vec3(2.0, 0.0, 0.0), 1e-9));
}

// A platform keyed to start at once at v = 1 m/s carries a box (mu = 1) resting on it: the
// box slips back by v^2 / (2 mu g) = 5.1 cm until friction has brought it up to speed, then
// rides along, and slips forward by as much when the platform stops dead
TEST(World, KeyedPlatformCarriesABoxWithCoulombSlip) {
  World world;
  BodyDesc platform = box_body(Vec3(3.0, 0.2, 2.0), 1.0, Vec3::Zero(), 3);
  platform.kinematic = true;
  platform.friction = 1.0;
  const int p = world.add_body(platform);
  world.set_kinematic_track(p, KinematicTrack({0.5, 2.5}, {Vec3::Zero(), Vec3(2.0, 0.0, 0.0)},
                                              {Quat::Identity(), Quat::Identity()}));
  BodyDesc box = box_body(Vec3::Constant(0.3), 1.0, Vec3(0.0, 0.25, 0.0), 3);
  box.friction = 1.0;
  world.add_body(box);
  const double slip = 1.0 / (2.0 * 1.0 * 9.81);
  for (int f = 0; f < 36; ++f) world.step_frame(1.0 / 24.0);  // t = 1.5 s, riding along
  EXPECT_NEAR(world.body_state(1).x.x() - world.body_mesh_pose(p).translation.x(), -slip, 0.1 * slip);
  EXPECT_NEAR(world.body_state(1).v.x(), 1.0, 1e-3);
  for (int f = 0; f < 36; ++f) world.step_frame(1.0 / 24.0);  // t = 3 s, stopped
  EXPECT_NEAR(world.body_state(1).x.x() - 2.0, 0.0, 0.1 * slip);
  EXPECT_NEAR(world.body_state(1).x.y(), 0.25, 2e-3);
}

// The worker threads are checked when the world is built: 0 (every CPU) to kMaxThreads; a
// count past it is refused (TBB's arena crashed at 100,000), whatever steps follow
TEST(World, ThreadsOutOfRangeAreRefused) {
  for (int threads : {-1, kMaxThreads + 1, 100000}) {
    WorldSettings settings;
    settings.threads = threads;
    EXPECT_THROW(World{settings}, std::invalid_argument) << threads;
  }
  for (int threads : {0, 1, 2, kMaxThreads}) {
    WorldSettings settings;
    settings.threads = threads;
    World world(settings);
    world.add_body(test::sphere_body(0.5, 1.0, Vec3(0.0, 2.0, 0.0)));
    EXPECT_GE(world.step_frame(1.0 / 24.0), 1) << threads;
  }
}

// Every stage has its name in the profile, and the kinematic bodies' move is timed apart
// from the broad phase
TEST(World, ProfileNamesEveryStage) {
  std::set<std::string> names;
  for (const char* name : kStageNames) names.insert(name);
  EXPECT_EQ(names.size(), static_cast<size_t>(kStageCount));
  EXPECT_EQ(std::string(kStageNames[static_cast<int>(Stage::kKinematicBodies)]), "kinematic_bodies");
  EXPECT_EQ(std::string(kStageNames[static_cast<int>(Stage::kBroadPhase)]), "broad_phase");
  EXPECT_EQ(std::string(kStageNames[static_cast<int>(Stage::kStatistics)]), "statistics");
  World world;
  world.add_body(test::sphere_body(0.5, 1.0, Vec3(0.0, 2.0, 0.0)));
  world.step_frame(1.0 / 24.0);
  EXPECT_GT(world.profile()[Stage::kBroadPhase], 0.0);
  EXPECT_GT(world.profile()[Stage::kKinematicBodies], 0.0);
}
