// Rigid bodies: a constant description (mass, inertia, shape, surface samples) kept apart
// from the small mutable state the solver touches every step.
//
// Frames. A body's mesh, level set and surface samples live in the mesh's own frame (the
// asset's coordinates). Dynamics use the principal frame: origin at the centre of mass, axes
// along the principal axes of inertia, so the inertia tensor is diagonal there. The state's
// orientation q turns principal-frame vectors into world vectors; the mesh frame is reached
// through def.mesh_axes (principal axes as columns, in mesh coordinates) and def.center.
#pragma once

#include "levelset/signed_distance.h"

#include <cmath>
#include <vector>

namespace simbake {

// Bounding sphere of a run of consecutive surface samples: a narrow phase that tests the
// sphere first skips whole runs far from the other body, and still visits the samples it
// keeps in their order
struct SampleBlock {
  static constexpr int kSize = 8;            // samples per block (the last may have fewer)
  Vec3 centre = Vec3::Zero();                // mesh coordinates (m)
  double radius = 0.0;                       // largest |sample - centre| (m)
  double margin = 0.0;                       // radius plus the block's part of the slack (m)

  // Whether a sample of the block may lie within `reach` of `point`, or below the plane
  // m.down + offset = 0 (m in mesh coordinates, down a unit vector). A slack of 1e-9 of the
  // lengths involved, far above round-off, makes a skipped block one whose every sample the
  // same test made sample by sample would also have rejected; the query's part of it is
  // computed once per query (slackened), the block's part is in margin
  static double slackened(const Vec3& point, double reach) { return reach + 1e-9 * (1.0 + point.norm() + reach); }
  static double slackened(double offset) { return 1e-9 * (1.0 + std::abs(offset)); }
  bool may_reach(const Vec3& point, double slackened_reach) const {
    const double far = slackened_reach + margin;
    return (centre - point).squaredNorm() <= far * far;
  }
  bool may_be_below(const Vec3& down, double offset, double offset_slack) const {
    return centre.dot(down) + offset < margin + offset_slack;
  }
  // Whether a sample of the block may lie in `box`, with the block's centre at `moved` in the
  // box's frame (a non-finite centre may: its samples are tested one by one)
  bool may_be_in(const Box3& box, const Vec3& moved) const {
    return !((moved.cwiseMax(box.min()).cwiseMin(box.max()) - moved).norm() > slackened(moved, margin));
  }
};

// The blocks of kSize consecutive samples, in sample order
std::vector<SampleBlock> sample_blocks(const Points& samples);

// The groups of kGroup consecutive blocks, each one sphere holding its blocks' spheres (its
// margin holds theirs: a group whose test fails holds no block whose test passes)
inline constexpr int kGroup = 8;
std::vector<SampleBlock> sample_groups(const std::vector<SampleBlock>& blocks);

struct RigidBodyDef {
  double inverse_mass = 0.0;                 // (1/kg); 0 for kinematic bodies
  Vec3 inertia = Vec3::Zero();               // principal moments (kg m^2)
  Vec3 inverse_inertia = Vec3::Zero();       // (1/(kg m^2)); 0 for kinematic bodies
  Vec3 center = Vec3::Zero();                // centre of mass in mesh coordinates (m)
  Mat3 mesh_axes = Mat3::Identity();         // principal axes in mesh coordinates, det +1
  double friction = 0.5;                     // Coulomb coefficient
  double restitution = 0.0;                  // in [0, 1]
  bool kinematic = false;                    // infinite mass, moved only by its own motion
  bool deforming = false;                    // kinematic, its surface moving (World::set_deforming_frame):
                                             // always a moving kinematic body
  bool isotropic = false;                    // equal principal moments (a cube, a sphere): the
                                             // torque-free rotation is exact, about L at |L| / I;
                                             // its mesh axes are its principal axes
  SignedDistancePtr shape;                   // signed distance in mesh coordinates; null when
                                             // nothing can touch the body (no grid baked)
  const BoxDistance* box = nullptr;          // the shape when it is a box (exact box contacts)
  const SphereDistance* sphere = nullptr;    // the shape when it is a sphere (exact sphere contacts)
  Points samples;                            // (s x 3) surface samples in mesh coordinates (m)
  std::vector<SampleBlock> sample_blocks;    // (ceil(s / 8)) their bounding spheres, in order
  std::vector<SampleBlock> sample_groups;    // (ceil(blocks / kGroup)) the blocks', likewise
  double bounding_radius = 0.0;              // largest |sample - center| (m)
  double thickness = 0.0;                    // smallest extent of the shape (m), for substeps
};

// Visits (visit(k)) every sample block k of the body that passes `test` (a SampleBlock ->
// bool that holds for a block's sphere whenever for one inside it: may_reach, may_be_below),
// in order, testing each group of blocks first and passing over the groups that fail
template <class Test, class Visit>
void for_sample_blocks(const RigidBodyDef& def, const Test& test, const Visit& visit) {
  const std::size_t count = def.sample_blocks.size();
  for (std::size_t g = 0; g < def.sample_groups.size(); ++g) {
    if (!test(def.sample_groups[g])) continue;
    const std::size_t end = std::min(count, (g + 1) * static_cast<std::size_t>(kGroup));
    for (std::size_t k = g * kGroup; k < end; ++k) {
      if (test(def.sample_blocks[k])) visit(k);
    }
  }
}

struct RigidBodyState {
  Vec3 x = Vec3::Zero();          // centre of mass, world (m)
  Quat q = Quat::Identity();      // principal frame -> world, unit
  Vec3 v = Vec3::Zero();          // linear velocity (m/s)
  Vec3 l = Vec3::Zero();          // angular momentum about the centre of mass, world (kg m^2/s)
};

// Rigid transform from mesh coordinates to world: world = rotation * mesh + translation
struct Pose {
  Mat3 rotation = Mat3::Identity();
  Vec3 translation = Vec3::Zero();
  Vec3 apply(const Vec3& p) const { return rotation * p + translation; }
  Vec3 apply_inverse(const Vec3& p) const { return rotation.transpose() * (p - translation); }
};

// Where the body's mesh is in the world for the centre of mass x and orientation q
Pose mesh_pose(const RigidBodyDef& def, const Vec3& x, const Quat& q);
inline Pose mesh_pose(const RigidBodyDef& def, const RigidBodyState& state) { return mesh_pose(def, state.x, state.q); }

// The centre of mass x and orientation q that put the mesh at the given pose (mesh origin and
// mesh orientation in world)
void set_mesh_pose(const RigidBodyDef& def, const Vec3& origin, const Quat& orientation, Vec3& x, Quat& q);
inline void set_mesh_pose(const RigidBodyDef& def, const Vec3& origin, const Quat& orientation,
                          RigidBodyState& state) {
  set_mesh_pose(def, origin, orientation, state.x, state.q);
}

// World-space inverse inertia R diag(1/I) R^T (1/(kg m^2)), from the principal inverse
// moments (1/(kg m^2)) and whether they are equal (RigidBodyDef::isotropic)
inline Mat3 world_inverse_inertia(const Vec3& inverse_inertia, bool isotropic, const Quat& q) {
  if (isotropic) return inverse_inertia[0] * Mat3::Identity();
  const Mat3 R = q.toRotationMatrix();
  return R * inverse_inertia.asDiagonal() * R.transpose();
}
inline Mat3 world_inverse_inertia(const RigidBodyDef& def, const Quat& q) {
  return world_inverse_inertia(def.inverse_inertia, def.isotropic, q);
}

// Angular velocity omega = I^-1 L (rad/s, world), likewise
inline Vec3 angular_velocity(const Vec3& inverse_inertia, bool isotropic, const Quat& q, const Vec3& l) {
  if (isotropic) return inverse_inertia[0] * l;
  const Vec3 body_l = q.conjugate() * l;
  return q * Vec3(inverse_inertia.cwiseProduct(body_l));
}
inline Vec3 angular_velocity(const RigidBodyDef& def, const Quat& q, const Vec3& l) {
  return angular_velocity(def.inverse_inertia, def.isotropic, q, l);
}
inline Vec3 angular_velocity(const RigidBodyDef& def, const RigidBodyState& state) {
  return angular_velocity(def, state.q, state.l);
}

// Torque-free rotation over dt with angular momentum L held fixed (Lie-Poisson splitting of
// the free rigid body into exact rotations about the three principal axes, composed
// symmetrically: 1/2, 2/2, 3, 2/2, 1/2 steps). L is conserved exactly, the energy error stays
// bounded (symplectic, time reversible), and the intermediate-axis instability appears as it
// should. McLachlan 1993; Touma and Wisdom 1994. A step turning the body more than 0.03 rad
// about an axis is taken in equal pieces (the error grows with the square of the turn).
// An isotropic body (def.isotropic) turns exactly, about L at the rate |L| / I, in one rotation.
Quat free_rotation(const RigidBodyDef& def, const Quat& q, const Vec3& l, double dt);

// How the end `to` of a torque-free turn from `from` turns with the angular momentum: the
// world rotation vector of the change per change of L, over dt (1/(kg m^2)), so that for small
// turns it is the world inverse inertia at `from` (`inverse_inertia`): the left Jacobian of the
// step's rotation times it. Exact for an isotropic body turning less than half a turn; for the
// others it takes the step as a turn at a fixed rate
inline Mat3 rotation_response(const Quat& from, const Quat& to, const Mat3& inverse_inertia) {
  return left_jacobian(rotation_vector_from_quat(to * from.conjugate())) * inverse_inertia;
}

// Rotation of a kinematic body spinning at a fixed world angular velocity omega over dt
Quat prescribed_rotation(const Quat& q, const Vec3& omega, double dt);

// Kinetic energy 1/2 M |v|^2 + 1/2 L.omega (J)
double kinetic_energy(const RigidBodyDef& def, const Vec3& v, const Quat& q, const Vec3& l);
inline double kinetic_energy(const RigidBodyDef& def, const RigidBodyState& state) {
  return kinetic_energy(def, state.v, state.q, state.l);
}

}  // namespace simbake
