// Joints against known answers: a compound pendulum's period (the exact elliptic-integral
// formula), a slider on an incline (g sin 30), a hinge's limit, a fixed pair as one rigid
// body, energy of an undriven mechanism, a 50-link chain and a mass ratio of 1000 held closed,
// drives, breaking, collision filtering, and the same bits on any number of threads.
#include <gtest/gtest.h>

#include "rigid/joints.h"
#include "test_support.h"

#include <algorithm>
#include <cmath>
#include <vector>

using namespace simbake;
using namespace simbake::test;

namespace {

constexpr double kG = 9.81;

// A rod (box) of length `length` along its y, pivot at its +y end
BodyDesc rod(double length, double mass, double angle, bool with_shape = true) {
  BodyDesc d = box_body(Vec3(0.1, length, 0.1), mass, Vec3::Zero());
  if (!with_shape) d.shape = nullptr;
  const Quat q(Eigen::AngleAxisd(angle, Vec3::UnitZ()));
  d.orientation = q;
  d.origin = -(q * Vec3(0.0, 0.5 * length, 0.0));  // pivot at the world origin
  return d;
}

// A hinge about world Z at the world origin holding the rod's top end (twist 0 at `angle`)
JointDesc hinge_to_world(int body, double length, double angle) {
  JointDesc j;
  j.type = JointType::kRevolute;
  j.body0 = kWorldBody;
  j.body1 = body;
  j.local_rotation0 = Quat(Eigen::AngleAxisd(angle, Vec3::UnitZ()));
  j.local_position1 = Vec3(0.0, 0.5 * length, 0.0);
  j.axis = 2;
  return j;
}

// The rod's angle from hanging straight down (rad), from its mesh pose
double rod_angle(const World& world, int body) {
  const Vec3 down = world.body_mesh_pose(body).rotation * Vec3(0.0, -1.0, 0.0);
  return std::atan2(down.x(), -down.y());
}

// Complete elliptic integral of the first kind K(k), by the arithmetic-geometric mean
double elliptic_k(double k) {
  double a = 1.0, b = std::sqrt(1.0 - k * k);
  for (int i = 0; i < 30; ++i) {
    const double m = 0.5 * (a + b);
    b = std::sqrt(a * b);
    a = m;
  }
  return M_PI / (2.0 * a);
}

double total_energy(const World& world) {
  double e = 0.0;
  for (int i = 0; i < world.body_count(); ++i) {
    const RigidBodyDef& def = world.body_def(i);
    if (def.kinematic) continue;
    const RigidBodyState s = world.body_state(i);
    e += kinetic_energy(def, s) + kG * s.x.y() / def.inverse_mass;
  }
  return e;
}

double worst_gap(const World& world) {
  double gap = 0.0;
  for (int j = 0; j < world.joint_count(); ++j) gap = std::max(gap, world.joint_error(j).gap);
  return gap;
}

// A chain of n links (boxes of `length` along x, no shape: they never collide), laid out
// horizontally (or `tilt` rad above) from the world origin, ball joints between their ends,
// the first to the world
World chain(int n, double length, double link_mass, double last_mass, int threads = 0, double tilt = 0.0) {
  WorldSettings settings;
  settings.threads = threads;
  World world(settings);
  for (int i = 0; i < n; ++i) {
    const double mass = i + 1 == n ? last_mass : link_mass;
    BodyDesc link = box_body(Vec3(length, 0.02, 0.02), mass, (i + 0.5) * length * Vec3(std::cos(tilt), std::sin(tilt), 0.0));
    link.orientation = Quat(Eigen::AngleAxisd(tilt, Vec3::UnitZ()));
    link.shape = nullptr;
    world.add_body(link);
    JointDesc j;
    j.type = JointType::kSpherical;
    j.body0 = i == 0 ? kWorldBody : i - 1;
    j.body1 = i;
    j.local_position0 = i == 0 ? Vec3::Zero() : Vec3(0.5 * length, 0.0, 0.0);
    j.local_position1 = Vec3(-0.5 * length, 0.0, 0.0);
    world.add_joint(j);
  }
  return world;
}

}  // namespace

// Period T = 4 sqrt(I / (m g d)) K(sin(theta0 / 2)), exact at any amplitude; amplitude kept
TEST(Joints, CompoundPendulumPeriod) {
  const double length = 1.0, mass = 2.0, theta0 = 30.0 * M_PI / 180.0;
  const double inertia = mass * (0.01 + length * length) / 12.0 + mass * 0.25 * length * length;
  const double expected = 4.0 * std::sqrt(inertia / (mass * kG * 0.5 * length)) * elliptic_k(std::sin(0.5 * theta0));
  for (int rate : {120, 240, 480}) {
    World world;
    world.add_body(rod(length, mass, theta0));
    world.add_joint(hinge_to_world(0, length, theta0));
    const double dt = 1.0 / rate;
    std::vector<double> crossings;  // downward zero crossings of the angle (s)
    double previous = rod_angle(world, 0), last_peak = 0.0, peak = 0.0;
    for (int k = 1; k <= 10 * rate; ++k) {
      world.step(dt);
      const double angle = rod_angle(world, 0);
      if (previous > 0.0 && angle <= 0.0) {
        crossings.push_back((k - 1 + previous / (previous - angle)) * dt);
        last_peak = peak;
        peak = 0.0;
      }
      peak = std::max(peak, std::abs(angle));
      previous = angle;
      EXPECT_LT(world.joint_error(0).gap, 1e-6);
    }
    ASSERT_GE(crossings.size(), 5u);
    const double period = (crossings.back() - crossings.front()) / (crossings.size() - 1);
    EXPECT_NEAR(period / expected, 1.0, 0.002) << "dt 1/" << rate;
    EXPECT_GT(last_peak / theta0, 0.95) << "dt 1/" << rate;
    RecordProperty("period_error_" + std::to_string(rate), std::to_string(period / expected - 1.0));
    std::printf("pendulum dt 1/%d: period %.6f s (exact %.6f, %+.4f%%), last amplitude %.4f of theta0\n", rate,
                period, expected, 100.0 * (period / expected - 1.0), last_peak / theta0);
  }
}

// A slider on a prismatic joint along a 30 degree incline accelerates at g sin 30 (axis X,
// and the same incline given as axis Y of a turned frame)
TEST(Joints, PrismaticSliderOnIncline) {
  const double slope = 30.0 * M_PI / 180.0;
  const Vec3 along(std::cos(slope), -std::sin(slope), 0.0);
  for (int axis : {0, 1}) {
    for (int rate : {60, 240}) {
      World world;
      world.add_body(box_body(Vec3(0.3, 0.2, 0.4), 3.0, Vec3(0.0, 1.0, 0.0)));
      JointDesc j;
      j.type = JointType::kPrismatic;
      j.body0 = kWorldBody;
      j.body1 = 0;
      j.axis = axis;
      const Quat frame(Eigen::AngleAxisd(axis == 0 ? -slope : -slope - M_PI / 2.0, Vec3::UnitZ()));
      j.local_position0 = Vec3(0.0, 1.0, 0.0);
      j.local_rotation0 = frame;
      j.local_rotation1 = frame;
      world.add_joint(j);
      const double dt = 1.0 / rate;
      std::vector<double> s;
      for (int k = 0; k <= rate; ++k) {
        if (k > 0) world.step(dt);
        s.push_back((world.body_state(0).x - Vec3(0.0, 1.0, 0.0)).dot(along));
      }
      const double from_velocity = world.body_state(0).v.dot(along) / 1.0;
      const double from_positions = (s[rate] - 2.0 * s[rate - 1] + s[rate - 2]) / (dt * dt);
      EXPECT_NEAR(from_velocity / (kG * 0.5), 1.0, 0.001) << "axis " << axis << " dt 1/" << rate;
      EXPECT_NEAR(from_positions / (kG * 0.5), 1.0, 0.001) << "axis " << axis << " dt 1/" << rate;
      const Vec3 off = world.body_state(0).x - Vec3(0.0, 1.0, 0.0);
      EXPECT_LT((off - off.dot(along) * along).norm(), 1e-6);
      EXPECT_LT(world.body_mesh_pose(0).rotation.isApprox(Mat3::Identity(), 1e-6) ? 0 : 1, 1);
      std::printf("slider axis %d dt 1/%d: a = %.6f (g sin 30 = %.6f)\n", axis, rate, from_velocity, kG * 0.5);
    }
  }
}

// A rod falling onto its hinge's lower limit, and one thrown at the upper, never pass them
TEST(Joints, RevoluteLimitHolds) {
  const double lower = -45.0 * M_PI / 180.0, upper = 20.0 * M_PI / 180.0;
  for (double spin : {0.0, 20.0}) {
    for (int rate : {120, 240}) {
      World world;
      const double start = M_PI / 2.0;  // horizontal, pointing +x
      BodyDesc body = rod(1.0, 1.0, start);
      body.angular_velocity = Vec3(0.0, 0.0, spin);
      world.add_body(body);
      JointDesc j = hinge_to_world(0, 1.0, start);
      j.lower_limit = lower;
      j.upper_limit = upper;
      world.add_joint(j);
      double low = 0.0, high = 0.0;
      for (int k = 0; k < 3 * rate; ++k) {
        world.step(1.0 / rate);
        const double turned = rod_angle(world, 0) - start;  // independent of the joint's twist
        low = std::min(low, turned);
        high = std::max(high, turned);
      }
      EXPECT_GT(low, lower - 0.5 * M_PI / 180.0);
      EXPECT_LT(high, upper + 0.5 * M_PI / 180.0);
      EXPECT_LT(low, lower + 1.0 * M_PI / 180.0);  // (it does reach the stop)
      std::printf("limit spin %.0f dt 1/%d: reached %.4f deg (limit %.1f), %.4f deg (limit %.1f)\n", spin, rate,
                  degrees(low), degrees(lower), degrees(high), degrees(upper));
    }
  }
}

// An undriven double pendulum (chaotic) gains no energy: the energy of the symplectic
// (SHAKE) step oscillates, bounded, by O(dt) about the true one, so the largest excursion
// above the start halves with the step (at most 0.6 of it at 1/480 s against 1/240 s: it
// vanishes as the step does, where a solver that feeds its joint error back as velocity
// would keep a gain) and is under 2% of m g L at 1/240 s
TEST(Joints, UndrivenMechanismGainsNoEnergy) {
  std::vector<double> gains;
  for (int rate : {240, 480}) {
    World world;
    world.add_body(rod(1.0, 1.0, M_PI / 2.0, false));
    BodyDesc second = rod(1.0, 1.0, M_PI / 2.0, false);
    second.origin += Vec3(1.0, 0.0, 0.0);
    world.add_body(second);
    world.add_joint(hinge_to_world(0, 1.0, M_PI / 2.0));
    JointDesc j = hinge_to_world(1, 1.0, M_PI / 2.0);
    j.body0 = 0;
    j.local_rotation0 = Quat::Identity();
    j.local_position0 = Vec3(0.0, -0.5, 0.0);
    world.add_joint(j);
    const double e0 = total_energy(world), mgl = 1.0 * kG * 1.0;
    double gain = 0.0, gap = 0.0, first = 0.0, last = 0.0;
    for (int k = 0; k < 10 * rate; ++k) {
      world.step(1.0 / rate);
      const double e = total_energy(world);
      gain = std::max(gain, e - e0);
      gap = std::max(gap, worst_gap(world));
      if (k < rate) first += e / rate;
      if (k >= 9 * rate) last += e / rate;
    }
    gains.push_back(gain);
    EXPECT_LT(gain, 0.02 * mgl) << "dt 1/" << rate;
    EXPECT_LT(gap, 1e-4);
    std::printf("double pendulum dt 1/%d: largest excursion above the start %.3e J (m g L = %.2f J); mean energy "
                "first second %.5f J, last second %.5f J; gap %.2e m\n", rate, gain, mgl, first, last, gap);
  }
  EXPECT_LE(gains[1], 0.6 * gains[0] + 1e-9);
}

// Two boxes glued by a fixed joint, thrown tumbling: they keep their relative pose, their
// centre of mass follows the parabola and their angular momentum about it is conserved
TEST(Joints, FixedPairMovesAsOneBody) {
  World world;
  BodyDesc a = box_body(Vec3(0.4, 0.2, 0.3), 2.0, Vec3(0.0, 5.0, 0.0));
  BodyDesc b = box_body(Vec3(0.2, 0.5, 0.2), 1.0, Vec3(0.3, 5.1, 0.05));
  a.shape = b.shape = nullptr;
  const Vec3 v0(1.0, 4.0, -0.5), w0(3.0, -7.0, 5.0);
  const Vec3 com0 = (2.0 * a.origin + 1.0 * b.origin) / 3.0;
  for (BodyDesc* d : {&a, &b}) {
    d->linear_velocity = v0 + w0.cross(d->origin - com0);
    d->angular_velocity = w0;
  }
  world.add_body(a);
  world.add_body(b);
  JointDesc j;
  j.type = JointType::kFixed;
  j.body0 = 0;
  j.body1 = 1;
  j.local_position0 = Vec3(0.3, 0.1, 0.05);
  world.add_joint(j);
  const auto relative = [&] {
    const Pose pa = world.body_mesh_pose(0), pb = world.body_mesh_pose(1);
    return std::make_pair(Vec3(pa.rotation.transpose() * (pb.translation - pa.translation)),
                          Quat(Mat3(pa.rotation.transpose() * pb.rotation)));
  };
  const auto [p0, q0] = relative();
  const auto momentum = [&] {
    const Vec3 com = (2.0 * world.body_state(0).x + world.body_state(1).x) / 3.0;
    Vec3 l = Vec3::Zero();
    for (int i = 0; i < 2; ++i) {
      const RigidBodyState s = world.body_state(i);
      l += s.l + (s.x - com).cross(s.v / world.body_def(i).inverse_mass);
    }
    return std::make_pair(com, l);
  };
  const Vec3 l0 = momentum().second;
  double worst_p = 0.0, worst_q = 0.0;
  const double dt = 1.0 / 240.0;
  for (int k = 1; k <= 480; ++k) {
    world.step(dt);
    const auto [p, q] = relative();
    worst_p = std::max(worst_p, (p - p0).norm());
    worst_q = std::max(worst_q, q.angularDistance(q0));
  }
  const double t = 480 * dt;
  const auto [com, l] = momentum();
  // (symplectic Euler's positions: x_n = x0 + v0 t + g dt^2 n (n + 1) / 2)
  const Vec3 expected = com0 + v0 * t + Vec3(0.0, -kG, 0.0) * dt * dt * 480 * 481 / 2.0;
  EXPECT_LT(worst_p, 1e-4);
  EXPECT_LT(degrees(worst_q), 0.05);
  EXPECT_LT((com - expected).norm(), 1e-9);
  EXPECT_LT((l - l0).norm(), 1e-6 * l0.norm());
  std::printf("fixed pair: pose error %.2e m, %.2e deg; angular momentum drift %.2e of |L|\n", worst_p,
              degrees(worst_q), (l - l0).norm() / l0.norm());
}

// A 50-link chain released horizontally, at the automatic substeps of 24 fps frames (its tip
// whips at tens of m/s): every joint within 1 mm at every frame over 10 s
TEST(Joints, FiftyLinkChainStaysClosed) {
  World world = chain(50, 0.1, 0.1, 0.1);
  double gap = 0.0, lowest = 0.0;
  for (int f = 0; f < 240; ++f) {
    world.step_frame(1.0 / 24.0);
    gap = std::max(gap, worst_gap(world));
    lowest = std::min(lowest, world.body_state(49).x.y());
  }
  EXPECT_LT(gap, 1e-3);
  EXPECT_LT(lowest, -4.5);  // (it fell and swung through hanging straight)
  std::printf("50-link chain, 10 s of 24 fps frames at automatic substeps: largest joint gap %.3e m\n", gap);
}

// Chains released at a tilt, at the automatic substeps of 24 fps frames: the energy at a
// frame's end never rises above the start (the whips are stepped again, shorter, where a
// substep turned too far) by more than the second-order term the frame's end velocity carries, twice the energy of a half
// kick of gravity over the longest substep, M (g dt / 2)^2 (a few mJ; the end velocity is
// taken as v - dt g / 2, see World::last_substep), and the velocities a frame ends with are
// the joints' own: both
// links' velocity at every joint's anchor the same (to round-off, where the position step
// alone leaves them apart by O(dt))
TEST(Joints, ReleasedChainsGainNoEnergyAndEndFramesWithJointVelocities) {
  for (const auto& [links, tilt] : {std::pair{20, 0.0}, std::pair{50, 0.5}, std::pair{35, -0.3}}) {
    World world = chain(links, 0.1, 0.1, 0.1, 0, tilt);
    const double e0 = total_energy(world), scale = 0.1 * links * kG * 0.1 * links / 2.0;
    double rise = 0.0, mismatch = 0.0, fastest = 0.0;
    for (int f = 0; f < 120; ++f) {
      world.step_frame(1.0 / 24.0);
      // (the frame's end velocities along gravity: see World::last_substep)
      double e = total_energy(world);
      for (int i = 0; i < links; ++i) {
        const double m = 1.0 / world.body_def(i).inverse_mass, vy = world.body_state(i).v.y(), end = vy - 0.5 * kG * world.last_substep();
        e += 0.5 * m * (end * end - vy * vy);
      }
      rise = std::max(rise, e - e0);
      for (int j = 0; j < world.joint_count(); ++j) {
        const JointDef& def = world.rigid_model().joints[j];
        const auto anchor_velocity = [&](int body, const Vec3& anchor) {
          if (body == kWorldBody) return Vec3(Vec3::Zero());
          const RigidBodyState s = world.body_state(body);
          return Vec3(s.v + angular_velocity(world.body_def(body), s).cross(s.q * anchor));
        };
        const Vec3 a = anchor_velocity(def.body0, def.anchor0), b = anchor_velocity(def.body1, def.anchor1);
        mismatch = std::max(mismatch, (a - b).norm());
        fastest = std::max(fastest, b.norm());
      }
    }
    const double dt = WorldSettings().max_substep, tolerance = 0.1 * links * std::pow(0.5 * kG * dt, 2);
    EXPECT_LE(rise, tolerance) << links << " links at " << tilt << " rad";
    EXPECT_LT(mismatch, 1e-9 * fastest) << links << " links at " << tilt << " rad";
    std::printf("chain of %d released at %.1f rad, 5 s: largest rise above the start %.2e J (of %.1f J; "
                "tolerance %.1e J); anchor velocities apart by %.1e m/s at most (fastest %.1f m/s)\n", links, tilt, rise, scale,
                tolerance, mismatch, fastest);
  }
}

// Two light links (10 g) carrying a 10 kg body, swinging from horizontal: mass ratio 1000,
// joints within 1 mm at every frame (automatic substeps)
TEST(Joints, MassRatioThousandStaysClosed) {
  World world = chain(3, 0.2, 0.01, 10.0);
  double gap = 0.0;
  for (int f = 0; f < 120; ++f) {
    world.step_frame(1.0 / 24.0);
    gap = std::max(gap, worst_gap(world));
  }
  EXPECT_LT(gap, 1e-3);
  std::printf("mass ratio 1000, 5 s: largest joint gap %.3e m\n", gap);
}

// Jointed bodies overlapping do not collide unless the joint says so
TEST(Joints, JointedPairSkipsCollision) {
  for (bool collide : {false, true}) {
    WorldSettings settings;
    settings.gravity = Vec3::Zero();
    World world(settings);
    world.add_body(box_body(Vec3::Constant(0.5), 1.0, Vec3::Zero(), 3));
    world.add_body(box_body(Vec3::Constant(0.5), 1.0, Vec3(0.45, 0.0, 0.0), 3));
    JointDesc j;
    j.type = JointType::kDistance;
    j.body0 = 0;
    j.body1 = 1;
    j.max_distance = 10.0;
    j.collision_enabled = collide;
    world.add_joint(j);
    for (int k = 0; k < 24; ++k) world.step(1.0 / 240.0);
    const double apart = (world.body_state(1).x - world.body_state(0).x).norm();
    if (collide) EXPECT_GT(apart, 0.4999);
    else EXPECT_NEAR(apart, 0.45, 1e-12);
  }
}

// Four chains solved in parallel: the same bits on one thread and on two
TEST(Joints, SameBitsOnAnyThreadCount) {
  std::vector<std::vector<double>> runs;
  for (int threads : {1, 2}) {
    WorldSettings settings;
    settings.threads = threads;
    World world(settings);
    for (int c = 0; c < 4; ++c) {
      for (int i = 0; i < 10; ++i) {
        BodyDesc link = box_body(Vec3(0.1, 0.02, 0.02), 0.1 + 0.01 * c, Vec3((i + 0.5) * 0.1, 0.0, c * 1.0));
        link.shape = nullptr;
        world.add_body(link);
        JointDesc j;
        j.type = c % 2 ? JointType::kRevolute : JointType::kSpherical;
        j.axis = 2;
        j.body0 = i == 0 ? kWorldBody : world.body_count() - 2;
        j.body1 = world.body_count() - 1;
        j.local_position0 = i == 0 ? Vec3(0.0, 0.0, c * 1.0) : Vec3(0.05, 0.0, 0.0);
        j.local_position1 = Vec3(-0.05, 0.0, 0.0);
        world.add_joint(j);
      }
    }
    for (int f = 0; f < 48; ++f) world.step_frame(1.0 / 24.0);
    std::vector<double> state;
    for (int i = 0; i < world.body_count(); ++i) {
      const RigidBodyState s = world.body_state(i);
      for (int k = 0; k < 3; ++k) state.insert(state.end(), {s.x[k], s.v[k], s.l[k]});
    }
    runs.push_back(state);
  }
  EXPECT_EQ(runs[0], runs[1]);
}

// A velocity drive (large damping, no stiffness) turns a rod hanging off-centre from its hinge
// against gravity's torque: its speed stays within 1% of the target over whole turns; force
// and acceleration drives
TEST(Joints, DriveHoldsTargetVelocity) {
  for (bool acceleration : {false, true}) {
    World world;
    world.add_body(rod(1.0, 1.0, 0.0));
    JointDesc j = hinge_to_world(0, 1.0, 0.0);
    JointDrive& drive = j.drives[kRotX + 2];  // (the hinge's axis, Z)
    drive.enabled = true;
    drive.damping = acceleration ? 1e5 : 1e4;  // (gravity's torque at most m g d = 4.9 N m)
    drive.target_velocity = 2.0;
    drive.acceleration = acceleration;
    world.add_joint(j);
    double worst = 0.0;
    for (int k = 0; k < 240 * 6; ++k) {
      world.step(1.0 / 240.0);
      const double w = angular_velocity(world.body_def(0), world.body_state(0)).z();
      if (k >= 240) worst = std::max(worst, std::abs(w / 2.0 - 1.0));
    }
    EXPECT_LT(worst, 0.01);
    std::printf("velocity drive (%s): speed within %.4f%% of the target over 5 s\n",
                acceleration ? "acceleration" : "force", 100.0 * worst);
  }
}

// A velocity drive at its bound gives its max_force, also when another joint shares the
// component: a wheel (box) with a bar glued across it, on a hinge to the world, spun up from
// rest at most T: alpha = T / (I_wheel + I_bar) from the boxes' moments, while below the target
TEST(Joints, DriveAtItsBoundGivesItsMaxForce) {
  for (double bar_mass : {0.2, 2.0, 20.0}) {
    WorldSettings settings;
    settings.gravity = Vec3::Zero();
    World world(settings);
    world.add_body(box_body(Vec3(0.8, 0.8, 0.1), 20.0, Vec3::Zero()));
    world.add_body(box_body(Vec3(0.76, 0.06, 0.12), bar_mass, Vec3::Zero()));
    JointDesc glue;
    glue.body0 = 0;
    glue.body1 = 1;
    world.add_joint(glue);
    JointDesc axle;
    axle.type = JointType::kRevolute;
    axle.body1 = 0;
    axle.axis = 2;
    axle.drives[kRotZ] = JointDrive{true, 0.0, 1e4, 0.0, 100.0, 10.0, false};
    world.add_joint(axle);
    const double inertia = 20.0 * (0.64 + 0.64) / 12.0 + bar_mass * (0.76 * 0.76 + 0.06 * 0.06) / 12.0;
    for (int k = 0; k < 240; ++k) world.step(1.0 / 240.0);
    const double alpha = angular_velocity(world.body_def(0), world.body_state(0)).z();  // (after 1 s)
    EXPECT_NEAR(alpha / (10.0 / inertia), 1.0, 1e-3) << "bar " << bar_mass;
    EXPECT_NEAR(angular_velocity(world.body_def(1), world.body_state(1)).z(), alpha, 1e-6 * alpha);
    std::printf("drive at its bound, bar %.1f kg: alpha %.6f rad/s^2 (T / I = %.6f)\n", bar_mass, alpha,
                10.0 / inertia);
  }
}

// A position drive holds a rod where its spring balances gravity's torque: the angle theta
// with ks (theta* - theta) = m g d sin(theta), solved here by bisection
TEST(Joints, PositionDriveBalancesGravity) {
  const double ks = 20.0, target = 60.0 * M_PI / 180.0, mgd = 1.0 * kG * 0.5;
  double lo = 0.0, hi = target;
  for (int i = 0; i < 100; ++i) {
    const double mid = 0.5 * (lo + hi);
    (ks * (target - mid) > mgd * std::sin(mid) ? lo : hi) = mid;
  }
  World world;
  world.add_body(rod(1.0, 1.0, 0.0));
  JointDesc j = hinge_to_world(0, 1.0, 0.0);
  j.drives[kRotZ] = JointDrive{true, ks, 5.0, target, 0.0, kUnlimited, false};
  world.add_joint(j);
  for (int k = 0; k < 240 * 20; ++k) world.step(1.0 / 240.0);
  EXPECT_NEAR(rod_angle(world, 0) / lo, 1.0, 1e-3);
  std::printf("position drive: rests at %.5f deg (balance %.5f deg)\n", degrees(rod_angle(world, 0)), degrees(lo));
}

// A 2 kg block hanging from the world by a fixed joint carries m g = 19.62 N: a break force
// 5% above holds for 3 s, 5% below breaks in the first step, for good; a torque likewise
TEST(Joints, BreaksPastItsForceOnly) {
  const double weight = 2.0 * kG;
  for (double factor : {1.05, 0.95}) {
    for (bool torque : {false, true}) {
      World world;
      world.add_body(box_body(Vec3(0.2, 0.2, 0.2), 2.0, Vec3(0.0, -0.5, 0.0)));
      JointDesc j;
      j.type = JointType::kFixed;
      j.body1 = 0;
      j.local_position0 = Vec3(torque ? 0.5 : 0.0, 0.0, 0.0);  // (off to the side: a torque of m g 0.5)
      j.local_position1 = Vec3(torque ? 0.5 : 0.0, 0.5, 0.0);
      (torque ? j.break_torque : j.break_force) = factor * weight * (torque ? 0.5 : 1.0);
      world.add_joint(j);
      int broke = -1;
      for (int k = 0; k < 720; ++k) {
        world.step(1.0 / 240.0);
        if (broke < 0 && !world.joint_state().enabled[0]) broke = k;
      }
      if (factor > 1.0) {
        EXPECT_EQ(broke, -1) << "torque " << torque;
        EXPECT_NEAR(world.joint_state().force[0].y(), weight, 1e-6 * weight);
        EXPECT_LT(world.body_state(0).v.norm(), 1e-9);
      } else {
        EXPECT_EQ(broke, 0) << "torque " << torque;
        EXPECT_NEAR(world.joint_state().broke_at[0], 1.0 / 240.0, 1e-12);
        EXPECT_NEAR(world.body_state(0).v.y(), -kG * 3.0, 0.05);  // (then falls freely)
      }
    }
  }
}

// A rod on a ball joint with a 30 degree cone (and on a D6 joint whose Y and Z turns are
// limited to 30 degrees, its twist to 10), knocked sideways hard: it never leaves the cone by
// more than half a degree, and reaches it; the D6's twist stays within its limit
TEST(Joints, ConeLimitHolds) {
  for (bool d6 : {false, true}) {
    World world;
    BodyDesc body = rod(1.0, 1.0, 0.0);
    body.angular_velocity = Vec3(12.0, 3.0, 18.0);
    world.add_body(body);
    JointDesc j;
    j.body1 = 0;
    j.local_position1 = Vec3(0.0, 0.5, 0.0);
    // (the cone about the joint frame's X, which both frames turn to the rod's -Y)
    j.local_rotation0 = j.local_rotation1 = Quat(Eigen::AngleAxisd(-M_PI / 2.0, Vec3::UnitZ()));
    const double cone = 30.0 * M_PI / 180.0, twist = 10.0 * M_PI / 180.0;
    if (d6) {
      j.type = JointType::kD6;
      for (int k = 0; k < 3; ++k) j.dof_lower[k] = 1.0, j.dof_upper[k] = -1.0;  // translations locked
      j.dof_lower[kRotX] = -twist;
      j.dof_upper[kRotX] = twist;
      for (int k : {kRotY, kRotZ}) j.dof_lower[k] = -cone, j.dof_upper[k] = cone;
    } else {
      j.type = JointType::kSpherical;
      j.cone_angle0 = j.cone_angle1 = cone;
    }
    world.add_joint(j);
    double widest = 0.0, turned = 0.0;
    for (int k = 0; k < 240 * 4; ++k) {
      world.step(1.0 / 240.0);
      const Mat3 r = world.body_mesh_pose(0).rotation;
      widest = std::max(widest, std::acos(std::clamp((r * Vec3::UnitY()).y(), -1.0, 1.0)));
      // (the joint's own measure of how far past its limits it is)
      turned = std::max(turned, std::abs(world.joint_error(0).angle));
    }
    EXPECT_LT(widest, cone + 0.5 * M_PI / 180.0) << "d6 " << d6;
    EXPECT_GT(widest, cone - 0.5 * M_PI / 180.0) << "d6 " << d6;
    EXPECT_LT(turned, 0.5 * M_PI / 180.0) << "d6 " << d6;
    std::printf("cone (%s): widest swing %.4f deg (cone 30), largest limit error %.2e deg\n",
                d6 ? "d6" : "spherical", degrees(widest), degrees(turned));
  }
}
