#include "rigid/rigid_body.h"

#include <algorithm>
#include <cmath>

namespace simbake {

std::vector<SampleBlock> sample_blocks(const Points& samples) {
  std::vector<SampleBlock> blocks;
  for (Eigen::Index first = 0; first < samples.rows(); first += SampleBlock::kSize) {
    const Eigen::Index count = std::min<Eigen::Index>(SampleBlock::kSize, samples.rows() - first);
    SampleBlock block;
    block.centre = samples.middleRows(first, count).colwise().mean().transpose();
    for (Eigen::Index k = first; k < first + count; ++k) {
      block.radius = std::max(block.radius, (samples.row(k).transpose() - block.centre).norm());
    }
    block.margin = block.radius + 1e-9 * (block.centre.norm() + block.radius);
    blocks.push_back(block);
  }
  return blocks;
}

std::vector<SampleBlock> sample_groups(const std::vector<SampleBlock>& blocks) {
  std::vector<SampleBlock> groups;
  for (std::size_t first = 0; first < blocks.size(); first += kGroup) {
    const std::size_t end = std::min(blocks.size(), first + kGroup);
    SampleBlock group;
    for (std::size_t k = first; k < end; ++k) group.centre += blocks[k].centre;
    group.centre /= static_cast<double>(end - first);
    double margin = 0.0;
    for (std::size_t k = first; k < end; ++k) {
      const double apart = (blocks[k].centre - group.centre).norm();
      group.radius = std::max(group.radius, apart + blocks[k].radius);
      margin = std::max(margin, apart + blocks[k].margin);
    }
    // (the slack again, for the round-off of the distances between the centres)
    group.margin = margin + 1e-9 * (group.centre.norm() + group.radius);
    groups.push_back(group);
  }
  return groups;
}

Pose mesh_pose(const RigidBodyDef& def, const Vec3& x, const Quat& q) {
  // a mesh point m sits at x + R(q) P^T (m - c): rotation R(q) P^T, translation x - R c
  Pose pose;
  // (an isotropic body's principal axes are its mesh axes: see RigidBodyDef::isotropic)
  pose.rotation = def.isotropic ? q.toRotationMatrix() : Mat3(q.toRotationMatrix() * def.mesh_axes.transpose());
  pose.translation = x - pose.rotation * def.center;
  return pose;
}

void set_mesh_pose(const RigidBodyDef& def, const Vec3& origin, const Quat& orientation, Vec3& x, Quat& q) {
  const Quat mesh_q = orientation.normalized();
  q = (mesh_q * Quat(def.mesh_axes)).normalized();
  x = origin + mesh_q * def.center;
}

Quat free_rotation(const RigidBodyDef& def, const Quat& q, const Vec3& l, double dt) {
  // An isotropic body's omega = L / I is constant in the world: q <- exp(dt omega) q, exact,
  // one rotation
  if (def.isotropic) return (quat_from_rotation_vector(dt * def.inverse_inertia[0] * l) * q).normalized();
  // In the body frame the angular momentum is b = R^T L. The flow of the k-th term of the
  // Hamiltonian H_k = b_k^2 / (2 I_k) rotates the body about its k-th axis by dt b_k / I_k
  // (q <- q rot_k) and b the opposite way (b <- rot_k^-1 b); b_k itself is unchanged.
  // The splitting's error grows with the square of the angle turned per step: a step that
  // turns the body more than kMaxTurn about any axis is taken as that many equal pieces (a
  // fast spinner then drifts as little at long steps as at short ones; a body at rest or
  // tumbling slowly takes one piece)
  static constexpr double kMaxTurn = 0.03;  // (rad)
  static constexpr int kAxis[5] = {0, 1, 2, 1, 0};
  static constexpr double kFraction[5] = {0.5, 0.5, 1.0, 0.5, 0.5};
  Quat result = q;
  Vec3 b = q.conjugate() * l;
  const double turn = std::abs(dt) * b.cwiseProduct(def.inverse_inertia).cwiseAbs().maxCoeff();
  const double wanted = std::ceil(turn / kMaxTurn);
  const int pieces = std::isfinite(wanted) ? static_cast<int>(std::clamp(wanted, 1.0, 64.0)) : 1;
  const double h = dt / pieces;
  for (int piece = 0; piece < pieces; ++piece) {
    for (int s = 0; s < 5; ++s) {
      const int k = kAxis[s];
      const double angle = kFraction[s] * h * b[k] * def.inverse_inertia[k];
      if (angle == 0.0) continue;
      const Quat rotation(Eigen::AngleAxisd(angle, Vec3::Unit(k)));
      result = result * rotation;
      b = rotation.conjugate() * b;
    }
  }
  return result.normalized();
}

Quat prescribed_rotation(const Quat& q, const Vec3& omega, double dt) {
  return (quat_from_rotation_vector(dt * omega) * q).normalized();
}

double kinetic_energy(const RigidBodyDef& def, const Vec3& v, const Quat& q, const Vec3& l) {
  if (def.kinematic) return 0.0;
  const double linear = 0.5 * v.squaredNorm() / def.inverse_mass;
  return linear + 0.5 * l.dot(angular_velocity(def, q, l));
}

}  // namespace simbake
