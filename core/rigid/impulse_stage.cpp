// Candidates, point velocities and the exchange of impulses (the method is in impulse_stage.h).
#include "rigid/impulse_stage.h"

#include "rigid/impulse.h"

#include <tbb/parallel_for.h>

namespace simbake {

void add_body_scratch(const RigidModel& model, const RigidData& data, RigidScratch& scratch) {
  const int i = model.body_count() - 1;
  scratch.candidate_x.push_back(data.x[i]);
  scratch.candidate_q.push_back(data.q[i]);
  scratch.candidate_v.push_back(data.v[i]);
  scratch.candidate_poses.push_back(body_mesh_pose(model, data, i));
  scratch.omega.push_back(Vec3::Zero());
  scratch.inverse_inertia.push_back(Mat3::Zero());
  scratch.stale.push_back(0);
  scratch.version.push_back(0);
  scratch.frozen.push_back(0);
  scratch.level.push_back(-1);
  scratch.boxes.emplace_back();
}

void begin_impulse_stage(const RigidModel& model, const RigidData& data, RigidScratch& scratch,
                         const WorldSettings& settings, double dt, bool with_forces, bool average_velocities) {
  scratch.dt = dt;
  scratch.candidates_with_forces = with_forces;
  scratch.average_velocities = average_velocities;
  // (each body on its own: in parallel)
  tbb::parallel_for(0, model.body_count(), [&](int i) {
    if (data.asleep[i]) return;
    const RigidBodyDef& def = model.defs[i];
    scratch.inverse_inertia[i] = def.kinematic ? Mat3::Zero() : world_inverse_inertia(def, data.q[i]);
    if (def.kinematic) scratch.omega[i] = data.spin[i];
    else if (!average_velocities) scratch.omega[i] = scratch.inverse_inertia[i] * data.l[i];
    update_candidate(model, data, scratch, settings, i);
  });
  scratch.log.stale.clear();
}

void update_candidate(const RigidModel& model, const RigidData& data, RigidScratch& scratch,
                      const WorldSettings& settings, int i) {
  const RigidBodyDef& def = model.defs[i];
  const double dt = scratch.dt;
  const Vec3& x = data.x[i];
  const Quat& q = data.q[i];
  if (def.kinematic) {
    scratch.candidate_x[i] = x + dt * data.v[i];
    scratch.candidate_q[i] = prescribed_rotation(q, data.spin[i], dt);
    scratch.candidate_v[i] = data.v[i];
  } else {
    const Vec3 v = scratch.candidates_with_forces ? Vec3(data.v[i] + dt * settings.gravity) : data.v[i];
    scratch.candidate_x[i] = x + dt * v;
    scratch.candidate_v[i] = v;
    scratch.candidate_q[i] = free_rotation(def, q, data.l[i], dt);
    if (scratch.average_velocities) {
      // (an isotropic body turns at L / I exactly, the rotation vector's shorter way round
      // while it turns less than half a turn in the step)
      const Vec3 spin = def.inverse_inertia[0] * data.l[i];
      scratch.omega[i] = def.isotropic && dt * spin.norm() < 3.0
                             ? spin
                             : Vec3(rotation_vector_from_quat(scratch.candidate_q[i] * q.conjugate()) / dt);
    }
  }
  scratch.candidate_poses[i] = mesh_pose(def, scratch.candidate_x[i], scratch.candidate_q[i]);
  scratch.stale[i] = 0;
  ++scratch.version[i];
}

void refresh_stale_candidates(const RigidModel& model, const RigidData& data, RigidScratch& scratch,
                              const WorldSettings& settings, ImpulseLog& log) {
  // (a body refreshed by a whole-world pass since it was listed is no longer stale)
  for (int i : log.stale) {
    if (scratch.stale[i]) update_candidate(model, data, scratch, settings, i);
  }
  log.stale.clear();
}

Pose pose_at(const RigidModel& model, const RigidData& data, const RigidScratch& scratch, int i, double s) {
  if (s >= 1.0) return scratch.candidate_poses[i];
  const Vec3 x = data.x[i] + s * (scratch.candidate_x[i] - data.x[i]);
  const Quat q = data.q[i].slerp(s, scratch.candidate_q[i]);
  return mesh_pose(model.defs[i], x, q);
}

Mat3 body_impulse_matrix(const RigidModel& model, const RigidScratch& scratch, int i, const Vec3& x) {
  if (i == kGround || model.defs[i].kinematic) return Mat3::Zero();
  return impulse_matrix(model.defs[i].inverse_mass, scratch.inverse_inertia[i], x - scratch.candidate_x[i]);
}

Mat3 pair_impulse_matrix(const RigidModel& model, const RigidScratch& scratch, const Penetration& p) {
  Mat3 K = Mat3::Zero();
  for (int i : {p.a, p.b}) {
    if (movable(model, scratch, i)) K += body_impulse_matrix(model, scratch, i, p.x);
  }
  return K;
}

void exchange_impulse(const RigidModel& model, RigidData& data, RigidScratch& scratch, const Penetration& p,
                      const Vec3& J, ImpulseLog& log) {
  double sign = 1.0;
  for (int i : {p.a, p.b}) {
    if (movable(model, scratch, i)) {
      const Vec3 dl = sign * (p.x - scratch.candidate_x[i]).cross(J);
      data.v[i] += sign * model.defs[i].inverse_mass * J;
      data.l[i] += dl;
      scratch.omega[i] += scratch.inverse_inertia[i] * dl;
      mark_stale(scratch, i, log);
      ++scratch.version[i];
    }
    sign = -1.0;
  }
  ++log.impulses;
}

void collect_impulses(RigidScratch& scratch) {
  IslandScratch& islands = scratch.islands;
  for (int k = 0; k < islands.count; ++k) {
    scratch.impulses += islands.logs[k].impulses;
    islands.logs[k].impulses = 0;
  }
  scratch.impulses += scratch.log.impulses;
  scratch.log.impulses = 0;
}

}  // namespace simbake
