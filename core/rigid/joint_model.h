// Joints between rigid bodies (UsdPhysics' joint schemas): their creation settings (JointDesc,
// what a scene says) and the constant definition the joints stage works with (JointDef).
//
// Frames. A joint has a frame on each of its two bodies: local_position/local_rotation in
// the body's mesh frame (the frame the body's pose is given in), or in the world for a
// joint to the world (body -1). The joint holds frame 1 to frame 0 in the ways its type says:
//   fixed      frames coincide
//   revolute   origins coincide, axes along `axis` coincide; a turn about it is free, or
//              limited to [lower_limit, upper_limit] (rad)
//   prismatic  orientations coincide, origin 1 on frame 0's `axis` line; a slide along it is
//              free or limited to [lower_limit, upper_limit] (m)
//   spherical  origins coincide; frame 1's `axis` within the cone about frame 0's of
//              half-angles cone_angle0 (towards the next axis) and cone_angle1 (towards the
//              one after) (rad; infinite: free)
//   distance   |origin 1 - origin 0| within [min_distance, max_distance] (m)
//   d6         each of the six degrees of freedom (transX, transY, transZ along frame 0's
//              axes; rotX twist, rotY and rotZ swing) free, locked (lower > upper, as
//              UsdPhysics' PhysicsLimitAPI writes it) or limited to [lower, upper] (m, rad)
// make_joint_def turns every type into one form: six degrees of freedom about frames turned
// so that a revolute's or prismatic's axis is X, plus the cone and distance limits.
#pragma once

#include "math/types.h"

#include <array>
#include <limits>

namespace simbake {

inline constexpr int kWorldBody = -1;  // a joint's body that is the world
inline constexpr double kUnlimited = std::numeric_limits<double>::infinity();

enum class JointType : int { kFixed, kRevolute, kPrismatic, kSpherical, kDistance, kD6 };

// A degree of freedom of a joint, in frame 0's axes: translations, then rotations
enum Dof : int { kTransX, kTransY, kTransZ, kRotX, kRotY, kRotZ, kDofCount };

// A drive on one degree of freedom (PhysicsDriveAPI): force = stiffness (target_position -
// position) + damping (target_velocity - velocity), at most max_force in magnitude; an
// acceleration drive's stiffness and damping are per unit of the joint's effective mass
struct JointDrive {
  bool enabled = false;
  double stiffness = 0.0;          // (N/m, or N m/rad; acceleration: 1/s^2)
  double damping = 0.0;            // (N s/m, or N m s/rad; acceleration: 1/s)
  double target_position = 0.0;    // (m, or rad)
  double target_velocity = 0.0;    // (m/s, or rad/s)
  double max_force = kUnlimited;   // (N, or N m)
  bool acceleration = false;       // false: force drive; true: acceleration drive
};

// Creation settings of one joint (World::add_joint checks them)
struct JointDesc {
  JointType type = JointType::kFixed;
  int body0 = kWorldBody;                       // body index, or kWorldBody
  int body1 = kWorldBody;
  Vec3 local_position0 = Vec3::Zero();          // joint frame in body 0's mesh frame (m)
  Quat local_rotation0 = Quat::Identity();
  Vec3 local_position1 = Vec3::Zero();          // and in body 1's
  Quat local_rotation1 = Quat::Identity();
  int axis = 0;                                 // revolute, prismatic, spherical: 0 X, 1 Y, 2 Z
  double lower_limit = -kUnlimited;             // revolute (rad), prismatic (m)
  double upper_limit = kUnlimited;
  double cone_angle0 = kUnlimited;              // spherical (rad)
  double cone_angle1 = kUnlimited;
  double min_distance = 0.0;                    // distance (m)
  double max_distance = kUnlimited;
  std::array<double, kDofCount> dof_lower;      // d6: per degree of freedom (m, rad); lower >
  std::array<double, kDofCount> dof_upper;      //   upper locks it; default free
  std::array<JointDrive, kDofCount> drives{};   // per degree of freedom of frame 0's axes (a
                                                //   revolute's drive on rot `axis`)
  double break_force = kUnlimited;              // (N) breaks for good when exceeded
  double break_torque = kUnlimited;             // (N m)
  bool enabled = true;                          // false: never acts
  bool collision_enabled = false;               // false: the two bodies never collide

  JointDesc() {
    dof_lower.fill(-kUnlimited);
    dof_upper.fill(kUnlimited);
  }
};

// What a degree of freedom may do
enum class DofMotion : int { kFree, kLocked, kLimited };

struct DofLimit {
  DofMotion motion = DofMotion::kFree;
  double lower = -kUnlimited, upper = kUnlimited;  // (m, rad) when limited
};

// The constant definition of a joint: every type as six degrees of freedom, frames in the
// bodies' principal frames (for the world: in the world), turned so the joint's axis is X
struct JointDef {
  JointType type = JointType::kFixed;
  int body0 = kWorldBody, body1 = kWorldBody;
  Vec3 anchor0 = Vec3::Zero();              // frame 0's origin, body 0's principal frame (m)
  Quat frame0 = Quat::Identity();           // frame 0's axes, body 0's principal frame
  Vec3 anchor1 = Vec3::Zero();
  Quat frame1 = Quat::Identity();
  std::array<DofLimit, kDofCount> dofs{};   // in the turned frame
  double cone0 = kUnlimited;                // swing limit towards Y and towards Z (rad); a
  double cone1 = kUnlimited;                //   locked swing axis is a zero half-angle
  bool cone = false;                        // the swing is limited by the cone
  bool distance = false;                    // translation: only min/max distance
  double min_distance = 0.0, max_distance = kUnlimited;  // (m)
  std::array<JointDrive, kDofCount> drives{};
  double break_force = kUnlimited;          // (N)
  double break_torque = kUnlimited;         // (N m)
  bool enabled = true;                      // at the start
  bool collision_enabled = false;
};

// Throws std::invalid_argument naming what is wrong with a joint's description (body
// indices against the `body_count` bodies there are)
void check_joint(const JointDesc& desc, int body_count);

}  // namespace simbake
