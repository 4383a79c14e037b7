// The rigid-body stages of World::step, after Guendelman, Bridson and Fedkiw, "Nonconvex rigid
// bodies with stacking" (SIGGRAPH 2003) and the seed notes.
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
//
// Materials. A pair's friction is the geometric mean sqrt(mu_a mu_b) and its restitution the
// larger of the two (both symmetric and both give back the common value when equal; max
// lets a bouncy ball bounce on a default, non-bouncy ground).
#include "rigid/impulse.h"
#include "world/world.h"

#include <algorithm>
#include <cmath>
#include <limits>

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

void World::begin_impulse_stage(double dt, bool with_forces, bool average_velocities) {
  dt_ = dt;
  candidates_with_forces_ = with_forces;
  average_velocities_ = average_velocities;
  for (int i = 0; i < body_count(); ++i) {
    const RigidBodyDef& def = defs_[i];
    inverse_inertia_[i] = def.kinematic ? Mat3::Zero() : world_inverse_inertia(def, states_[i].q);
    if (def.kinematic) omega_[i] = spin_[i];
    else if (!average_velocities) omega_[i] = inverse_inertia_[i] * states_[i].l;
    update_candidate(i);
  }
}

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
    if (average_velocities_) omega_[i] = rotation_vector_from_quat(c.q * s.q.conjugate()) / dt_;
  }
  candidate_poses_[i] = mesh_pose(def, c);
  stale_[i] = 0;
}

void World::refresh_stale_candidates() {
  for (int i = 0; i < body_count(); ++i) {
    if (stale_[i]) update_candidate(i);
  }
}

Vec3 World::point_velocity(int i, const Vec3& x) const {
  if (i == kGround) return Vec3::Zero();
  return states_[i].v + omega_[i].cross(x - candidates_[i].x);
}

// ---------------------------------------------------------------------------------------
// Narrow phase: the samples of body a tested against b's level set at the candidates.
// The normal is b's level-set gradient turned into world space with b's candidate rotation.

void World::find_penetrations(int a, int b, bool only_approaching, std::vector<Penetration>& out) const {
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
    if (only_approaching && (point_velocity(a, x) - point_velocity(b, x)).dot(n) >= 0.0) continue;
    out.push_back({a, b, x, n, phi, static_cast<int>(s)});
  }
}

// K = K_a + K_b at the point, lever arms from the candidate centres of mass; immovable
// bodies (ground, kinematic, frozen) contribute nothing
Mat3 World::pair_impulse_matrix(const Penetration& p) const {
  Mat3 K = Mat3::Zero();
  for (int i : {p.a, p.b}) {
    if (movable(i)) K += impulse_matrix(defs_[i].inverse_mass, inverse_inertia_[i], p.x - candidates_[i].x);
  }
  return K;
}

// Body a takes J and body b takes -J, in linear and angular momentum; the stage's angular
// velocity follows (exactly for start-of-step velocities, to first order for average ones)
// and the candidate is marked stale
void World::exchange_impulse(const Penetration& p, const Vec3& J) {
  double sign = 1.0;
  for (int i : {p.a, p.b}) {
    if (movable(i)) {
      const Vec3 dl = sign * (p.x - candidates_[i].x).cross(J);
      states_[i].v += sign * defs_[i].inverse_mass * J;
      states_[i].l += dl;
      omega_[i] += inverse_inertia_[i] * dl;
      stale_[i] = 1;
    }
    sign = -1.0;
  }
  ++stats_.impulses;
}

// ---------------------------------------------------------------------------------------
// Collisions (elastic): per pair and sweep, one impulse at the deepest non-separating point
// found in either direction, with start-of-step velocities; the impulse changes the
// candidates of both bodies at once. Pairs are visited in a different order every sweep
// (a deterministic shuffle seeded by the step and sweep numbers) so that no body is always
// served first.

bool World::apply_collision_impulse(const Penetration& p, double restitution, double friction) {
  const Vec3 v = point_velocity(p.a, p.x) - point_velocity(p.b, p.x);
  if (v.dot(p.n) >= 0.0) return false;
  exchange_impulse(p, coulomb_impulse(pair_impulse_matrix(p), p.n, v, restitution, friction));
  refresh_stale_candidates();
  return true;
}

namespace {

// Fisher-Yates with a fixed generator (splitmix64): the same order on every platform
void deterministic_shuffle(std::vector<int>& order, std::uint64_t seed) {
  auto next = [&seed] {
    std::uint64_t z = (seed += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  };
  for (std::size_t k = order.size(); k > 1; --k) std::swap(order[k - 1], order[next() % k]);
}

}  // namespace

void World::resolve_collisions(double dt) {
  begin_impulse_stage(dt, /*with_forces=*/true, /*average_velocities=*/false);
  std::vector<int> order(pairs_.size());
  std::vector<Penetration>& found = scratch_;
  for (int sweep = 0; sweep < settings_.collision_sweeps; ++sweep) {
    for (std::size_t k = 0; k < order.size(); ++k) order[k] = static_cast<int>(k);
    deterministic_shuffle(order, static_cast<std::uint64_t>(stats_.substeps) * 64 + sweep);
    bool any = false;
    for (int index : order) {
      const BodyPair& pair = pairs_[index];
      found.clear();
      find_penetrations(pair.a, pair.b, true, found);
      if (pair.b != kGround) find_penetrations(pair.b, pair.a, true, found);
      if (found.empty()) continue;
      const auto deepest = std::min_element(found.begin(), found.end(),
          [](const Penetration& l, const Penetration& r) { return l.phi < r.phi; });
      any |= apply_collision_impulse(*deepest, pair.restitution, pair.friction);
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
  begin_impulse_stage(dt, /*with_forces=*/false, /*average_velocities=*/true);
  contacts_.clear();
  contact_keys_.clear();
  for (int sweep = 0; sweep < settings_.contact_sweeps; ++sweep) {
    refresh_stale_candidates();
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
    find_penetrations(pair.a, pair.b, false, scratch_);
    if (pair.b != kGround) find_penetrations(pair.b, pair.a, false, scratch_);
    std::stable_sort(scratch_.begin(), scratch_.end(),
                     [](const Penetration& l, const Penetration& r) { return l.phi < r.phi; });
    for (const Penetration& p : scratch_) {
      const std::uint64_t key = contact_key(p);
      if (!contact_keys_.insert(key).second) continue;
      contacts_.push_back({p, pair.friction});
    }
  }
}

std::uint64_t World::contact_key(const Penetration& p) {
  return (std::uint64_t(p.a + 1) << 43) | (std::uint64_t(p.b + 1) << 22) | std::uint64_t(p.sample);
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

// Contact impulse at one contact point: one projected Gauss-Seidel update of the point's
// total impulse this stage (see contact_impulse_update); only the change is applied.
bool World::apply_contact_impulse(ContactPoint& contact) {
  const Penetration& p = contact.point;
  if (!movable(p.a) && !movable(p.b)) return false;
  const Mat3 K = pair_impulse_matrix(p);
  const Vec3 v = point_velocity(p.a, p.x) - point_velocity(p.b, p.x);
  const Vec3 total = contact_impulse_update(K, p.n, v, contact.total, contact.friction);
  const Vec3 change = total - contact.total;
  if ((K * change).norm() <= settings_.contact_tolerance) return false;
  contact.total = total;
  exchange_impulse(p, change);
  return true;
}

// ---------------------------------------------------------------------------------------
// Shock propagation (Guendelman et al. 2003, section 7): the iterations above need many
// sweeps to carry the weight of a tall stack down to the ground. Instead, the contact graph
// is levelled by breadth-first search from the bodies that touch the ground or a kinematic
// body (level 0); each level in turn is solved with every level below frozen (infinite
// mass), so the bottom of a stack is settled first and then holds everything above it.
// Bodies connected to nothing immovable keep the result of the sweeps.

void World::assign_contact_levels() {
  const int n = body_count();
  std::fill(level_.begin(), level_.end(), -1);
  std::vector<std::vector<int>> neighbours(n);
  std::vector<int> queue;
  for (const ContactPoint& c : contacts_) {
    const int a = c.point.a, b = c.point.b;
    const bool a_fixed = defs_[a].kinematic, b_fixed = b == kGround || defs_[b].kinematic;
    if (b_fixed && !a_fixed && level_[a] < 0) { level_[a] = 0; queue.push_back(a); }
    if (a_fixed && !b_fixed && level_[b] < 0) { level_[b] = 0; queue.push_back(b); }
    if (!a_fixed && !b_fixed) {
      neighbours[a].push_back(b);
      neighbours[b].push_back(a);
    }
  }
  for (std::size_t head = 0; head < queue.size(); ++head) {
    const int i = queue[head];
    for (int j : neighbours[i]) {
      if (level_[j] < 0) {
        level_[j] = level_[i] + 1;
        queue.push_back(j);
      }
    }
  }
}

void World::propagate_shocks() {
  if (contacts_.empty()) return;
  assign_contact_levels();
  const int top = *std::max_element(level_.begin(), level_.end());
  // the ground and kinematic bodies sit below level 0; unconnected bodies above every level
  auto level_of = [&](int i) {
    if (i == kGround || defs_[i].kinematic) return -1;
    return level_[i] >= 0 ? level_[i] : std::numeric_limits<int>::max();
  };
  for (int level = 0; level <= top; ++level) {
    for (int sweep = 0; sweep < settings_.shock_sweeps; ++sweep) {
      refresh_stale_candidates();
      bool any = false;
      for (ContactPoint& contact : contacts_) {
        if (std::max(level_of(contact.point.a), level_of(contact.point.b)) != level) continue;
        refresh_contact(contact.point);
        any |= apply_contact_impulse(contact);
      }
      if (!any) break;
    }
    for (int i = 0; i < body_count(); ++i) {
      if (level_[i] == level) frozen_[i] = 1;
    }
  }
  std::fill(frozen_.begin(), frozen_.end(), 0);
  refresh_stale_candidates();
}


// Positions: x += dt v and the torque-free rotation with the final L (what the contact
// stage's average velocities assumed)
void World::update_positions(double dt) {
  dt_ = dt;
  candidates_with_forces_ = false;
  average_velocities_ = false;
  for (int i = 0; i < body_count(); ++i) {
    update_candidate(i);
    states_[i].x = candidates_[i].x;
    states_[i].q = candidates_[i].q;
  }
}

}  // namespace simbake
