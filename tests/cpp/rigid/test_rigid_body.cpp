// Free flight of a single rigid body: torque-free spin, frames and poses.
#include <gtest/gtest.h>

#include "test_support.h"

#include <random>
#include <vector>

using namespace simbake;

namespace {

RigidBodyDef brick_def() {
  // a 1 x 0.5 x 0.25 m brick of 10 kg
  const Vec3 size(1.0, 0.5, 0.25);
  RigidBodyDef def;
  const MassProperties props = box_mass_properties(size);
  def.inverse_mass = 0.1;
  def.inertia = (10.0 / props.volume) * props.inertia.diagonal();
  def.inverse_inertia = def.inertia.cwiseInverse();
  return def;
}

}  // namespace

TEST(RigidBody, MeshPoseRoundTrip) {
  RigidBodyDef def = brick_def();
  def.center = Vec3(0.1, 0.2, 0.3);
  def.mesh_axes = Eigen::AngleAxisd(0.4, Vec3(0, 0, 1)).toRotationMatrix();
  const Quat orientation(Eigen::AngleAxisd(1.1, Vec3(1, 1, 0).normalized()));
  RigidBodyState state;
  set_mesh_pose(def, Vec3(1.0, 2.0, 3.0), orientation, state);
  const Pose pose = mesh_pose(def, state);
  EXPECT_TRUE(pose.translation.isApprox(Vec3(1.0, 2.0, 3.0), 1e-12));
  EXPECT_TRUE(pose.rotation.isApprox(orientation.toRotationMatrix(), 1e-12));
  // the centre of mass is where the mesh's centre lands
  EXPECT_TRUE(pose.apply(def.center).isApprox(state.x, 1e-12));
}

// For a symmetric body the exact motion is a steady rotation about L; the splitting is a
// second-order method, so its one-step error must fall by ~8 when dt halves
TEST(RigidBody, SplittingIsSecondOrderOnASymmetricBody) {
  RigidBodyDef def;
  def.inverse_inertia = Vec3::Constant(0.5);
  const Vec3 l(0.3, -1.2, 2.0);
  const Quat q0(Eigen::AngleAxisd(0.3, Vec3::UnitX()));
  auto error = [&](double dt) {
    const Quat q = free_rotation(def, q0, l, dt);
    const Quat exact = quat_from_rotation_vector(dt * 0.5 * l) * q0;
    return q.angularDistance(exact);
  };
  EXPECT_LT(error(0.01), 1e-4);
  EXPECT_GT(error(0.02) / error(0.01), 7.0);
}

// Spin about the axis of the intermediate moment, slightly perturbed: the energy and the
// angular momentum stay put, and the body flips over (the Dzhanibekov effect), as the exact
// solution does. The world angular momentum is measured independently of the state's L,
// from the rotation actually taken each step: L = I(q) omega_avg.
TEST(RigidBody, TorqueFreeSpinConservesMomentumAndEnergyAndFlips) {
  const RigidBodyDef def = brick_def();
  for (double dt : {1.0 / 60.0, 1.0 / 240.0}) {
    RigidBodyState s;
    const Vec3 omega0(0.01, 6.0, 0.01);  // rad/s, about principal axis 1 (intermediate)
    s.l = def.inertia.cwiseProduct(omega0);
    const double energy0 = kinetic_energy(def, s);
    const Vec3 l0 = s.l;
    double worst_energy = 0.0, worst_momentum = 0.0;
    bool flipped = false;
    const int steps = static_cast<int>(std::lround(8.0 / dt));
    for (int k = 0; k < steps; ++k) {
      const Quat next = free_rotation(def, s.q, s.l, dt);
      // momentum from the realized rotation, with the inertia at the midpoint orientation
      const Vec3 omega_avg = rotation_vector_from_quat(next * s.q.conjugate()) / dt;
      const Quat mid = s.q.slerp(0.5, next);
      const Mat3 R = mid.toRotationMatrix();
      const Vec3 l_measured = R * def.inertia.asDiagonal() * R.transpose() * omega_avg;
      worst_momentum = std::max(worst_momentum, (l_measured - l0).norm() / l0.norm());
      s.q = next;
      worst_energy = std::max(worst_energy, std::abs(kinetic_energy(def, s) - energy0) / energy0);
      // the body's intermediate axis turned against the momentum: flipped
      if ((s.q * Vec3::UnitY()).dot(l0) < 0.0) flipped = true;
    }
    EXPECT_LT(worst_momentum, 0.01) << "dt " << dt;
    EXPECT_LT(worst_energy, 0.01) << "dt " << dt;
    EXPECT_TRUE(flipped) << "dt " << dt;
  }
}

TEST(RigidBody, StableAxisSpinDoesNotFlip) {
  const RigidBodyDef def = brick_def();
  RigidBodyState s;
  s.l = def.inertia.cwiseProduct(Vec3(0.05, 0.05, 6.0));  // about the largest moment
  const Vec3 l0 = s.l;
  for (int k = 0; k < 8 * 240; ++k) {
    s.q = free_rotation(def, s.q, s.l, 1.0 / 240.0);
    ASSERT_GT((s.q * Vec3::UnitZ()).dot(l0.normalized()), 0.99);
  }
}

// rotation_response of a free_rotation step (how the end turns per change of L, over dt)
// against central differences of the end itself: exact for an isotropic body (1e-6 of it, the
// differences' own error at h = 1e-5); for the brick, taken as a fixed-rate turn, off by less
// than the step's turn (rad) relative to it
TEST(RigidBody, RotationResponseMatchesFiniteDifferences) {
  RigidBodyDef ball;
  ball.inertia = Vec3::Constant(0.4);
  ball.inverse_inertia = ball.inertia.cwiseInverse();
  ball.isotropic = true;
  const Vec3 l(0.7, -1.1, 0.9);
  const Quat q0(Eigen::AngleAxisd(0.8, Vec3(1, 2, -1).normalized()));
  const double h = 1e-5;
  for (const auto& [def, dt] : {std::pair{ball, 0.3}, std::pair{brick_def(), 0.05}}) {
    const Quat end = free_rotation(def, q0, l, dt);
    const Mat3 response = rotation_response(q0, end, world_inverse_inertia(def, q0));
    Mat3 differences;
    for (int k = 0; k < 3; ++k) {
      const Vec3 dl = h * Vec3::Unit(k);
      const Quat plus = free_rotation(def, q0, l + dl, dt), minus = free_rotation(def, q0, l - dl, dt);
      differences.col(k) = (rotation_vector_from_quat(plus * end.conjugate()) -
                            rotation_vector_from_quat(minus * end.conjugate())) / (2.0 * h * dt);
    }
    const double turn = end.angularDistance(q0);
    const double error = (response - differences).norm() / differences.norm();
    if (def.isotropic) {
      EXPECT_LT(error, 1e-6);
    } else {
      EXPECT_GT(turn, 0.05);
      EXPECT_LT(error, turn);
    }
    std::printf("rotation response (%s): step turn %.3f rad, relative error %.2e\n", def.isotropic ? "ball" : "brick", turn, error);
  }
}

// The groups of sample blocks only pass over what the blocks' own tests would reject: for
// the samples of a torus-like ring (blocks spread around it) and points near and far, with
// reaches from a hair to the whole ring, for_sample_blocks visits exactly the blocks whose
// own may_reach holds (and, below planes, whose may_be_below holds), in order, and skips
// whole groups where it can
TEST(RigidBody, SampleGroupsVisitExactlyTheBlocksThatPass) {
  Points samples(1000, 3);
  for (int k = 0; k < samples.rows(); ++k) {
    const double u = 0.0251 * k, v = 0.37 * k;
    samples.row(k) << (1.0 + 0.3 * std::cos(v)) * std::cos(u), 0.3 * std::sin(v), (1.0 + 0.3 * std::cos(v)) * std::sin(u);
  }
  RigidBodyDef def;
  def.samples = samples;
  def.sample_blocks = sample_blocks(samples);
  def.sample_groups = sample_groups(def.sample_blocks);
  ASSERT_EQ(def.sample_groups.size(), (def.sample_blocks.size() + kGroup - 1) / kGroup);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> unit(-1.0, 1.0), reach(0.0, 1.5);
  long long skipped = 0;
  for (int query = 0; query < 2000; ++query) {
    const Vec3 point = 1.5 * Vec3(unit(rng), unit(rng), unit(rng));
    const double slackened = SampleBlock::slackened(point, reach(rng));
    const Vec3 down = Vec3(unit(rng), unit(rng), unit(rng)).normalized();
    const double offset = unit(rng), offset_slack = SampleBlock::slackened(offset);
    for (int test = 0; test < 2; ++test) {
      auto passes = [&](const SampleBlock& b) {
        return test == 0 ? b.may_reach(point, slackened) : b.may_be_below(down, offset, offset_slack);
      };
      std::vector<std::size_t> expected, visited;
      for (std::size_t k = 0; k < def.sample_blocks.size(); ++k) {
        if (passes(def.sample_blocks[k])) expected.push_back(k);
      }
      for_sample_blocks(def, passes, [&](std::size_t k) { visited.push_back(k); });
      ASSERT_EQ(visited, expected) << "query " << query << " test " << test;
      for (const SampleBlock& group : def.sample_groups) skipped += !passes(group);
    }
  }
  EXPECT_GT(skipped, 1000);  // (the groups do pass over blocks)
  // a group's sphere holds its blocks' samples
  for (std::size_t k = 0; k < def.sample_blocks.size(); ++k) {
    const SampleBlock& group = def.sample_groups[k / kGroup];
    for (Eigen::Index s = k * SampleBlock::kSize; s < std::min<Eigen::Index>((k + 1) * SampleBlock::kSize, samples.rows()); ++s) {
      EXPECT_LE((samples.row(s).transpose() - group.centre).norm(), group.radius * (1.0 + 1e-12));
    }
  }
}
