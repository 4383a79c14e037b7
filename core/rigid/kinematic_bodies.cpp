#include "rigid/kinematic_bodies.h"

namespace simbake {

void move_kinematic_bodies(const RigidModel& model, RigidData& data, double time, double dt) {
  for (int i = 0; i < model.body_count(); ++i) {
    if (model.tracks[i].empty()) continue;
    Vec3 origin, origin_next;
    Quat orientation, orientation_next;
    model.tracks[i].pose_at(time, origin, orientation);
    set_mesh_pose(model.defs[i], origin, orientation, data.x[i], data.q[i]);
    if (dt <= 0.0) {
      data.v[i] = Vec3::Zero();
      data.spin[i] = Vec3::Zero();
      continue;
    }
    model.tracks[i].pose_at(time + dt, origin_next, orientation_next);
    Vec3 next_x;
    Quat next_q;
    set_mesh_pose(model.defs[i], origin_next, orientation_next, next_x, next_q);
    data.v[i] = (next_x - data.x[i]) / dt;
    data.spin[i] = rotation_vector_from_quat(next_q * data.q[i].conjugate()) / dt;
  }
}

}  // namespace simbake
