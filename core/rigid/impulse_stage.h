// What the two impulse stages (rigid/collisions.h, rigid/contacts.h) and shock propagation
// share, after Guendelman, Bridson and Fedkiw, "Nonconvex rigid bodies with stacking"
// (SIGGRAPH 2003) and the seed notes.
//
// Candidates. Both impulse stages work on candidate end-of-step states: the collision stage
// advances x by dt (v + dt g) (forces included) and q by the torque-free rotation; the
// contact stage, after gravity has been added to v, advances x by dt v. Every impulse
// changes the start-of-step v and L of the bodies it touches, and so their candidates, which
// are recomputed at once.
//
// Velocities at a point, v = V + omega x (x - X) with X the candidate centre of mass.
// Collisions use start-of-step velocities, omega = I^-1 L (updated exactly by each impulse,
// omega += I^-1 (r x J)). Contacts use the average velocities that update_positions will
// realize, as the notes' "Average velocities" slide requires: V_avg = (X(t+dt) - X(t)) / dt
// = V, and omega_avg = unrotate(q_new q^-1) / dt with q_new the candidate orientation. Within
// a contact sweep omega_avg follows each impulse to first order (the same I^-1 (r x J)); the
// candidates and omega_avg are recomputed exactly at the start of every sweep, so once the
// sweeps converge the velocities are exactly the average ones.
#pragma once

#include "rigid/rigid_scratch.h"
#include "world/world_settings.h"

namespace simbake {

// Starts an impulse stage of step dt: every awake body's world I^-1, its angular velocity at
// points (I^-1 L, unless the stage uses average velocities) and its candidate. Each body on
// its own, in parallel
void begin_impulse_stage(const RigidModel& model, const RigidData& data, RigidScratch& scratch,
                         const WorldSettings& settings, double dt, bool with_forces, bool average_velocities);

// Body i's candidate from its state now (and, for average velocities, its omega); its
// version bumped
void update_candidate(const RigidModel& model, const RigidData& data, RigidScratch& scratch,
                      const WorldSettings& settings, int i);

// Marks body i's candidate as behind its velocities; the log's list keeps the refresh in
// proportion to the bodies that took impulses, not to the world
inline void mark_stale(RigidScratch& scratch, int i, ImpulseLog& log) {
  if (!scratch.stale[i]) log.stale.push_back(i);
  scratch.stale[i] = 1;
}

// The stale candidates of the log's bodies brought up to date
void refresh_stale_candidates(const RigidModel& model, const RigidData& data, RigidScratch& scratch,
                              const WorldSettings& settings, ImpulseLog& log);

// The velocity of body i's point x in the stage under way (m/s; the ground is at rest)
inline Vec3 point_velocity(const RigidData& data, const RigidScratch& scratch, int i, const Vec3& x) {
  if (i == kGround) return Vec3::Zero();
  if (!scratch.surfaces.empty() && scratch.surfaces[i]) return scratch.surfaces[i]->velocity_at(x);
  return data.v[i] + scratch.omega[i].cross(x - scratch.candidate_x[i]);
}

// Whether an impulse moves body i: not the ground, a kinematic or a frozen body
inline bool movable(const RigidModel& model, const RigidScratch& scratch, int i) {
  return i != kGround && !model.defs[i].kinematic && !scratch.frozen[i];
}

// Mesh pose of body i at fraction s of the step, between its start and its candidate
Pose pose_at(const RigidModel& model, const RigidData& data, const RigidScratch& scratch, int i, double s);

// Body i's K at world point x, lever arm from its candidate centre of mass; zero for the
// ground and kinematic bodies (rigid/impulse.h)
Mat3 body_impulse_matrix(const RigidModel& model, const RigidScratch& scratch, int i, const Vec3& x);

// K = K_a + K_b at the point; immovable bodies (ground, kinematic, frozen) contribute nothing
Mat3 pair_impulse_matrix(const RigidModel& model, const RigidScratch& scratch, const Penetration& p);

// Body a takes J and body b takes -J, in linear and angular momentum; the stage's angular
// velocity follows (exactly for start-of-step velocities, to first order for average ones)
// and the candidate is marked stale
void exchange_impulse(const RigidModel& model, RigidData& data, RigidScratch& scratch, const Penetration& p,
                      const Vec3& J, ImpulseLog& log);

// The impulses of the stage so far into scratch.impulses (the logs' counts are summed after
// the parallel part, so the total is the same on any number of threads)
void collect_impulses(RigidScratch& scratch);

}  // namespace simbake
