// Joints: a description checked, and turned into the six-degrees-of-freedom definition the
// joints stage solves (joint_model.h says what each type holds).
#include "rigid/joint_model.h"

#include "rigid/rigid_model.h"

#include <cmath>
#include <stdexcept>
#include <string>

namespace simbake {

namespace {

void require(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument(what);
}

bool not_nan(double x) { return !std::isnan(x); }

void check_drive(const JointDrive& drive) {
  if (!drive.enabled) return;
  require(drive.stiffness >= 0.0 && std::isfinite(drive.stiffness), "joint drive stiffness must be finite and >= 0");
  require(drive.damping >= 0.0 && std::isfinite(drive.damping), "joint drive damping must be finite and >= 0");
  require(std::isfinite(drive.target_position) && std::isfinite(drive.target_velocity),
          "joint drive targets must be finite");
  require(drive.max_force >= 0.0 && not_nan(drive.max_force), "joint drive max_force must be >= 0");
}

// The frame whose axes are frame's, turned cyclically so that its X is frame's axis `axis`
// (X, Y, Z -> Y, Z, X for axis 1; Z, X, Y for axis 2): a proper rotation
Quat turned(const Quat& frame, int axis) {
  if (axis == 0) return frame;
  Mat3 cycle;
  if (axis == 1) cycle << 0, 0, 1, 1, 0, 0, 0, 1, 0;  // columns e_y, e_z, e_x
  else cycle << 0, 1, 0, 0, 0, 1, 1, 0, 0;            // columns e_z, e_x, e_y
  return (frame * Quat(cycle)).normalized();
}

// The same cyclic turn of a per-degree-of-freedom array: entry k of the result is entry
// (k + axis) mod 3 of its translations, likewise of its rotations
template <class T>
std::array<T, kDofCount> cycled(const std::array<T, kDofCount>& a, int axis) {
  std::array<T, kDofCount> out = a;
  for (int k = 0; k < 3; ++k) {
    out[k] = a[(k + axis) % 3];
    out[3 + k] = a[3 + (k + axis) % 3];
  }
  return out;
}

DofLimit limit_of(double lower, double upper) {
  if (lower > upper) return {DofMotion::kLocked, 0.0, 0.0};
  if (lower == -kUnlimited && upper == kUnlimited) return {DofMotion::kFree, lower, upper};
  return {DofMotion::kLimited, lower, upper};
}

// A joint frame given in a body's mesh frame, in its principal frame (kWorldBody: as given)
void to_principal(const RigidModel& model, int body, const Vec3& p, const Quat& r, Vec3& anchor, Quat& frame) {
  if (body == kWorldBody) {
    anchor = p;
    frame = r.normalized();
    return;
  }
  // a mesh point m sits at x + R(q) P^T (m - c) (rigid_body.cpp, mesh_pose)
  const RigidBodyDef& def = model.defs[body];
  const Mat3 axes = def.isotropic ? Mat3::Identity() : def.mesh_axes;
  anchor = axes.transpose() * (p - def.center);
  frame = (Quat(Mat3(axes.transpose())) * r.normalized()).normalized();
}

}  // namespace

void check_joint(const JointDesc& desc, int body_count) {
  const auto valid = [&](int b) { return b == kWorldBody || (b >= 0 && b < body_count); };
  require(valid(desc.body0) && valid(desc.body1), "joint body index out of range");
  require(desc.body0 != desc.body1, "a joint needs two different bodies (or one and the world)");
  require(desc.local_position0.allFinite() && desc.local_position1.allFinite(), "joint local positions must be finite");
  require(desc.local_rotation0.coeffs().allFinite() && desc.local_rotation0.norm() > 0.0 &&
              desc.local_rotation1.coeffs().allFinite() && desc.local_rotation1.norm() > 0.0,
          "joint local rotations must be finite, nonzero quaternions");
  require(desc.axis >= 0 && desc.axis <= 2, "joint axis must be X, Y or Z");
  require(not_nan(desc.lower_limit) && not_nan(desc.upper_limit), "joint limits must not be NaN");
  if (desc.type == JointType::kRevolute && desc.lower_limit <= desc.upper_limit) {
    require((desc.lower_limit >= -M_PI - 1e-9 || desc.lower_limit == -kUnlimited) &&
                (desc.upper_limit <= M_PI + 1e-9 || desc.upper_limit == kUnlimited),
            "revolute joint limits must lie within [-180, 180] degrees");
  }
  require(desc.cone_angle0 >= 0.0 && desc.cone_angle1 >= 0.0, "spherical joint cone angles must be >= 0");
  require(desc.min_distance >= 0.0 && std::isfinite(desc.min_distance) && not_nan(desc.max_distance) &&
              desc.max_distance >= desc.min_distance,
          "distance joint needs 0 <= min_distance <= max_distance");
  for (int k = 0; k < kDofCount; ++k) {
    require(not_nan(desc.dof_lower[k]) && not_nan(desc.dof_upper[k]), "joint limits must not be NaN");
    check_drive(desc.drives[k]);
  }
  require(desc.break_force > 0.0 && desc.break_torque > 0.0, "joint break force and torque must be > 0");
}

JointDef make_joint_def(const RigidModel& model, const JointDesc& desc) {
  JointDef def;
  def.type = desc.type;
  def.body0 = desc.body0;
  def.body1 = desc.body1;
  def.break_force = desc.break_force;
  def.break_torque = desc.break_torque;
  def.enabled = desc.enabled;
  def.collision_enabled = desc.collision_enabled;
  // the degrees of freedom in the joint's own frames, then turned so its axis is X
  std::array<DofLimit, kDofCount> dofs;
  const DofLimit locked{DofMotion::kLocked, 0.0, 0.0}, free{};
  const DofLimit range = limit_of(desc.lower_limit, desc.upper_limit);
  int axis = desc.axis;
  switch (desc.type) {
    case JointType::kFixed: dofs.fill(locked); break;
    case JointType::kRevolute: dofs.fill(locked); dofs[kRotX + axis] = range; break;
    case JointType::kPrismatic: dofs.fill(locked); dofs[kTransX + axis] = range; break;
    case JointType::kSpherical:
      dofs = {locked, locked, locked, free, free, free};
      def.cone = std::isfinite(desc.cone_angle0) || std::isfinite(desc.cone_angle1);
      def.cone0 = desc.cone_angle0;
      def.cone1 = desc.cone_angle1;
      break;
    case JointType::kDistance:
      dofs = {free, free, free, free, free, free};
      def.distance = true;
      def.min_distance = desc.min_distance;
      def.max_distance = desc.max_distance;
      axis = 0;
      break;
    case JointType::kD6: {
      for (int k = 0; k < kDofCount; ++k) dofs[k] = limit_of(desc.dof_lower[k], desc.dof_upper[k]);
      // one rotation not locked: a hinge about it (turned to X); more: twist about X and a
      // swing cone of the limits about Y and Z (a locked one: zero)
      int open = 0, last_open = 0;
      for (int k = 0; k < 3; ++k) {
        if (dofs[kRotX + k].motion != DofMotion::kLocked) { ++open; last_open = k; }
      }
      axis = open == 1 ? last_open : 0;
      if (open >= 2) {
        const auto half_angle = [](const DofLimit& d) {
          return d.motion == DofMotion::kLocked ? 0.0 : std::max(std::abs(d.lower), std::abs(d.upper));
        };
        def.cone1 = half_angle(dofs[kRotY]);  // about Y: X towards Z
        def.cone0 = half_angle(dofs[kRotZ]);  // about Z: X towards Y
        def.cone = std::isfinite(def.cone0) || std::isfinite(def.cone1);
        dofs[kRotY] = dofs[kRotZ] = free;
      }
      break;
    }
  }
  def.dofs = cycled(dofs, axis);
  def.drives = cycled(desc.drives, axis);
  to_principal(model, desc.body0, desc.local_position0, turned(desc.local_rotation0, axis), def.anchor0, def.frame0);
  to_principal(model, desc.body1, desc.local_position1, turned(desc.local_rotation1, axis), def.anchor1, def.frame1);
  return def;
}

}  // namespace simbake
