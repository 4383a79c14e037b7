// The mutable half of the rigid bodies: their state at the start of a step, one entry per body
// in contiguous arrays (bodies are addressed by index), and their sleep. Changed only by the
// rigid stages (rigid/*.h) and by the world applying what a cloth's contacts did to the bodies
// (world/cloth_coupling.h).
#pragma once

#include "rigid/rigid_model.h"

#include <vector>

namespace simbake {

// The joints' state: whether each acts, and what it did over the last step
struct JointState {
  std::vector<char> enabled;      // (njoint) acting; a broken joint stays disabled
  std::vector<double> broke_at;   // (njoint) world time it broke (s); NaN while whole
  std::vector<Vec3> force;        // (njoint x 3) force on body 1 over the last step, world (N)
  std::vector<Vec3> torque;       // (njoint x 3) torque of its angular rows on body 1 (N m)
};

struct RigidData {
  // motion
  std::vector<Vec3> x;          // (nbody x 3) centre of mass, world (m)
  std::vector<Quat> q;          // (nbody x 4) orientation: principal frame -> world, unit
  std::vector<Vec3> v;          // (nbody x 3) velocity of the centre of mass (m/s)
  std::vector<Vec3> l;          // (nbody x 3) angular momentum about the centre of mass, world (kg m^2/s)
  std::vector<Vec3> spin;       // (nbody x 3) kinematic bodies' prescribed angular velocity,
                                //   world (rad/s); zero for dynamic bodies
  // sleep (rigid/sleeping.h)
  std::vector<char> asleep;     // (nbody) sleeping: skipped by every stage
  std::vector<double> rest_time;  // (nbody) time spent resting so far (s)
  std::vector<Vec3> rest_x;     // (nbody x 3) where the current rest began: centre of mass (m)
  std::vector<Quat> rest_q;     //   and orientation
  std::vector<int> island;      // (nbody) union-find parent; for sleepers, their island
  JointState joints;            // the joints' state
};

// Appends body i's state, from its checked description and constant def
void add_body_state(const BodyDesc& desc, const RigidBodyDef& def, RigidData& data);

// Body i's state as one record
inline RigidBodyState body_state(const RigidData& data, int i) { return {data.x[i], data.q[i], data.v[i], data.l[i]}; }

// Where body i's mesh is in the world now
inline Pose body_mesh_pose(const RigidModel& model, const RigidData& data, int i) {
  return mesh_pose(model.defs[i], data.x[i], data.q[i]);
}

// Body i's angular velocity now (rad/s, world): a kinematic body's prescribed spin, else I^-1 L
inline Vec3 body_angular_velocity(const RigidModel& model, const RigidData& data, int i) {
  return model.defs[i].kinematic ? data.spin[i] : angular_velocity(model.defs[i], data.q[i], data.l[i]);
}

// A kinematic body moving in this step (keyed, with a velocity of its own, or deforming)
inline bool moving_kinematic(const RigidModel& model, const RigidData& data, int i) {
  return model.defs[i].kinematic &&
         (model.defs[i].deforming || data.v[i] != Vec3::Zero() || data.spin[i] != Vec3::Zero());
}

}  // namespace simbake
