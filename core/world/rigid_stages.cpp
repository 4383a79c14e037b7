// The rigid-body stages of World::step, after Guendelman, Bridson and Fedkiw, "Nonconvex rigid
// bodies with stacking" (SIGGRAPH 2003) and the seed notes.
//
// Candidates. Both impulse stages work on candidate end-of-step states: the collision stage
// advances x by dt (v + dt g) (forces included) and q by the torque-free rotation; the
// contact stage, after gravity has been added to v, advances x by dt v. Every impulse
// changes the start-of-step v and L of the bodies it touches, and so their candidates, which
// are recomputed at once.
//
// Velocities at a point. Collisions use start-of-step velocities, v = V + omega x (x - X).
// Contacts use the average velocities that update_positions will realize, as the notes'
// "Average velocities" slide requires: V_avg = (X(t+dt) - X(t)) / dt = V, and
// omega_avg = unrotate(q_new q^-1) / dt with q_new the candidate orientation.
//
// Materials. A pair's friction is the geometric mean sqrt(mu_a mu_b) and its restitution the
// larger of the two (both symmetric and both give back the common value when equal; max
// lets a bouncy ball bounce on a default, non-bouncy ground).
#include "rigid/impulse.h"
#include "world/world.h"

#include <algorithm>
#include <cmath>

namespace simbake {

namespace {

double combine_friction(double a, double b) { return std::sqrt(a * b); }
double combine_restitution(double a, double b) { return std::max(a, b); }

// Box around a body's bounding sphere at both ends of a straight move, grown by `margin`
Box3 swept_box(const Vec3& from, const Vec3& to, double radius, double margin) {
  Box3 box(from.cwiseMin(to), from.cwiseMax(to));
  box.min().array() -= radius + margin;
  box.max().array() += radius + margin;
  return box;
}

}  // namespace

// ---------------------------------------------------------------------------------------
// Broad phase: keep only pairs whose boxes over the step overlap. The box of a body holds
// its bounding sphere at the start and at the forced candidate, plus a margin for what
// impulses may add during the step.

void World::broad_phase(double dt) {
  pairs_.clear();
  const int n = body_count();
  std::vector<Box3> boxes(n);
  for (int i = 0; i < n; ++i) {
    const RigidBodyState& s = states_[i];
    const Vec3 gravity = defs_[i].kinematic ? Vec3::Zero() : settings_.gravity;
    const Vec3 to = s.x + dt * (s.v + dt * gravity);
    const double margin = 0.5 * dt * (s.v.norm() + dt * gravity.norm()) + 1e-4;
    boxes[i] = swept_box(s.x, to, defs_[i].bounding_radius, margin);
  }
  for (int a = 0; a < n; ++a) {
    if (ground_ && !defs_[a].kinematic && boxes[a].min().y() <= ground_->height) {
      pairs_.push_back({a, kGround, combine_friction(defs_[a].friction, ground_->friction),
                        combine_restitution(defs_[a].restitution, ground_->restitution)});
    }
    for (int b = a + 1; b < n; ++b) {
      if (defs_[a].kinematic && defs_[b].kinematic) continue;
      if (!boxes[a].intersects(boxes[b])) continue;
      pairs_.push_back({a, b, combine_friction(defs_[a].friction, defs_[b].friction),
                        combine_restitution(defs_[a].restitution, defs_[b].restitution)});
    }
  }
}

// ---------------------------------------------------------------------------------------
// Candidates and point velocities

void World::update_candidate(int i) {
  const RigidBodyDef& def = defs_[i];
  const RigidBodyState& s = states_[i];
  RigidBodyState& c = candidates_[i];
  c = s;
  if (def.kinematic) {
    c.x = s.x + dt_ * s.v;
    c.q = prescribed_rotation(s.q, spin_[i], dt_);
  } else {
    const Vec3 v = candidates_with_forces_ ? Vec3(s.v + dt_ * settings_.gravity) : s.v;
    c.x = s.x + dt_ * v;
    c.v = v;
    c.q = free_rotation(def, s.q, s.l, dt_);
  }
  candidate_poses_[i] = mesh_pose(def, c);
}

void World::update_all_candidates(double dt, bool with_forces) {
  dt_ = dt;
  candidates_with_forces_ = with_forces;
  for (int i = 0; i < body_count(); ++i) update_candidate(i);
}

Vec3 World::point_velocity(int i, const Vec3& x, Velocities mode) const {
  if (i == kGround) return Vec3::Zero();
  const RigidBodyDef& def = defs_[i];
  const RigidBodyState& s = states_[i];
  Vec3 omega;
  if (def.kinematic) {
    omega = spin_[i];
  } else if (mode == Velocities::kStartOfStep) {
    omega = angular_velocity(def, s);
  } else {
    omega = rotation_vector_from_quat(candidates_[i].q * s.q.conjugate()) / dt_;
  }
  return s.v + omega.cross(x - candidates_[i].x);
}

// ---------------------------------------------------------------------------------------
// Narrow phase: the samples of body a tested against b's level set at the candidates.
// The normal is b's level-set gradient turned into world space with b's candidate rotation.

void World::find_penetrations(int a, int b, Velocities mode, bool only_approaching,
                              std::vector<Penetration>& out) const {
  if (b != kGround && !defs_[b].shape) return;  // nothing can enter a body without a shape
  const Pose& pose_a = candidate_poses_[a];
  const Points& samples = defs_[a].samples;
  Box3 local_bounds;
  if (b != kGround) local_bounds = defs_[b].shape->bounds();
  for (Eigen::Index s = 0; s < samples.rows(); ++s) {
    const Vec3 x = pose_a.apply(samples.row(s).transpose());
    double phi;
    Vec3 n;
    if (b == kGround) {
      phi = x.y() - ground_->height;
      if (phi >= 0.0) continue;
      n = Vec3::UnitY();
    } else {
      const Pose& pose_b = candidate_poses_[b];
      const Vec3 p = pose_b.apply_inverse(x);
      if (!local_bounds.contains(p)) continue;  // outside b's box is outside b
      Vec3 n_local;
      phi = defs_[b].shape->phi_and_normal(p, n_local);
      if (phi >= 0.0) continue;
      n = pose_b.rotation * n_local;
    }
    if (only_approaching) {
      const Vec3 v = point_velocity(a, x, mode) - point_velocity(b, x, mode);
      if (v.dot(n) >= 0.0) continue;
    }
    out.push_back({a, b, x, n, phi, static_cast<int>(s)});
  }
}

// K = K_a + K_b at the point, with lever arms from the candidate centres of mass
Mat3 World::pair_impulse_matrix(const Penetration& p) const {
  Mat3 K = Mat3::Zero();
  for (int i : {p.a, p.b}) {
    if (i == kGround || defs_[i].kinematic) continue;
    K += impulse_matrix(defs_[i].inverse_mass, world_inverse_inertia(defs_[i], states_[i].q),
                        p.x - candidates_[i].x);
  }
  return K;
}

// Body a takes J and body b takes -J, in linear and angular momentum; candidates follow
void World::exchange_impulse(const Penetration& p, const Vec3& J) {
  double sign = 1.0;
  for (int i : {p.a, p.b}) {
    if (i != kGround && !defs_[i].kinematic) {
      states_[i].v += sign * defs_[i].inverse_mass * J;
      states_[i].l += sign * (p.x - candidates_[i].x).cross(J);
      update_candidate(i);
    }
    sign = -1.0;
  }
  ++stats_.impulses;
}

// Collision impulse at one penetrating point; false when the point is already separating
bool World::apply_impulse(const Penetration& p, double restitution, double friction, Velocities mode) {
  const Vec3 v = point_velocity(p.a, p.x, mode) - point_velocity(p.b, p.x, mode);
  if (v.dot(p.n) >= 0.0) return false;
  exchange_impulse(p, coulomb_impulse(pair_impulse_matrix(p), p.n, v, restitution, friction));
  return true;
}

// Contact impulse at one contact point: one projected Gauss-Seidel update of the point's
// total impulse this stage (see contact_impulse_update); only the change is applied.
bool World::apply_contact_impulse(ContactPoint& contact) {
  const Penetration& p = contact.point;
  const Mat3 K = pair_impulse_matrix(p);
  const Vec3 v = point_velocity(p.a, p.x, Velocities::kAverage) - point_velocity(p.b, p.x, Velocities::kAverage);
  const Vec3 total = contact_impulse_update(K, p.n, v, contact.total, contact.friction);
  const Vec3 change = total - contact.total;
  if ((K * change).norm() <= settings_.contact_tolerance) return false;
  contact.total = total;
  exchange_impulse(p, change);
  return true;
}

// ---------------------------------------------------------------------------------------
// Collisions (elastic): per pair and sweep, one impulse at the deepest non-separating point
// found in either direction, with start-of-step velocities.

void World::resolve_collisions(double dt) {
  update_all_candidates(dt, /*with_forces=*/true);
  std::vector<Penetration>& found = scratch_;
  for (int sweep = 0; sweep < settings_.collision_sweeps; ++sweep) {
    bool any = false;
    for (const BodyPair& pair : pairs_) {
      found.clear();
      find_penetrations(pair.a, pair.b, Velocities::kStartOfStep, true, found);
      if (pair.b != kGround) find_penetrations(pair.b, pair.a, Velocities::kStartOfStep, true, found);
      if (found.empty()) continue;
      const auto deepest = std::min_element(found.begin(), found.end(),
          [](const Penetration& l, const Penetration& r) { return l.phi < r.phi; });
      any |= apply_impulse(*deepest, pair.restitution, pair.friction, Velocities::kStartOfStep);
    }
    if (!any) break;
  }
}

// Velocities: gravity on every dynamic body (no torque: it acts at the centre of mass)
void World::update_velocities(double dt) {
  for (int i = 0; i < body_count(); ++i) {
    if (!defs_[i].kinematic) states_[i].v += dt * settings_.gravity;
  }
}

// ---------------------------------------------------------------------------------------
// Contacts (inelastic): every sample that penetrates at the candidates becomes a contact
// point for the rest of the stage (deepest first within a pair); each sweep re-evaluates
// every contact at the bodies' current candidates with average velocities, until no
// impulse changes anything.

void World::resolve_contacts(double dt) {
  update_all_candidates(dt, /*with_forces=*/false);
  contacts_.clear();
  contact_keys_.clear();
  for (int sweep = 0; sweep < settings_.contact_sweeps; ++sweep) {
    find_new_contacts();
    bool any = false;
    for (ContactPoint& contact : contacts_) {
      refresh_contact(contact.point);
      any |= apply_contact_impulse(contact);
    }
    if (!any) break;
  }
}

void World::find_new_contacts() {
  for (const BodyPair& pair : pairs_) {
    scratch_.clear();
    find_penetrations(pair.a, pair.b, Velocities::kAverage, false, scratch_);
    if (pair.b != kGround) find_penetrations(pair.b, pair.a, Velocities::kAverage, false, scratch_);
    std::stable_sort(scratch_.begin(), scratch_.end(),
                     [](const Penetration& l, const Penetration& r) { return l.phi < r.phi; });
    for (const Penetration& p : scratch_) {
      const std::uint64_t key = (std::uint64_t(p.a + 1) << 43) | (std::uint64_t(p.b + 1) << 22) |
                                std::uint64_t(p.sample);
      if (contact_keys_.insert(key).second) contacts_.push_back({p, pair.friction});
    }
  }
}

// Moves a contact's sample with its body's candidate and takes b's normal there
void World::refresh_contact(Penetration& p) const {
  p.x = candidate_poses_[p.a].apply(defs_[p.a].samples.row(p.sample).transpose());
  if (p.b == kGround) {
    p.phi = p.x.y() - ground_->height;
    p.n = Vec3::UnitY();
  } else {
    const Pose& pose_b = candidate_poses_[p.b];
    Vec3 n_local;
    p.phi = defs_[p.b].shape->phi_and_normal(pose_b.apply_inverse(p.x), n_local);
    p.n = pose_b.rotation * n_local;
  }
}

// Positions: x += dt v and the torque-free rotation with the final L (what the contact
// stage's average velocities assumed)
void World::update_positions(double dt) {
  dt_ = dt;
  candidates_with_forces_ = false;
  for (int i = 0; i < body_count(); ++i) {
    update_candidate(i);
    states_[i].x = candidates_[i].x;
    states_[i].q = candidates_[i].q;
  }
}

}  // namespace simbake
