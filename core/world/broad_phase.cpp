// The broad phase and sleeping: what lets the cost of a step follow the bodies that move.
//
// Broad phase. Each body's box holds its bounding sphere at the start of the step and at the
// candidate with gravity, grown by a margin for what impulses may add during the step. Boxes
// are binned into a uniform grid (see overlapping_pairs), so the cost is O(n + pairs) rather
// than O(n^2). The pair list is sorted by index, so the order in which later stages see
// pairs depends only on the scene.
//
// Sleeping. Bodies are grouped into islands connected through this step's contact points
// (the ground and kinematic bodies do not connect). A body is at rest while none of its points
// has strayed further than sleep_speed * sleep_time / 2 from where it was when its rest began
// (so the bottom of a loaded pile, whose velocities flicker at the solver's tolerance without
// going anywhere, counts as resting). When every body of an island has rested for sleep_time
// seconds the island sleeps: its velocities are zeroed and every stage skips it. A sleeping
// island wakes when an awake dynamic body or a moving kinematic body touches it: a sample of
// one inside the other, the awake body taken where it will be at the end of the step. Mere
// box overlap does not wake it, so a settled part of a pile sleeps beside a part still
// sliding.
//
// Materials. A pair's friction is the geometric mean sqrt(mu_a mu_b) and its restitution the
// larger of the two (both symmetric and both give back the common value when equal; max
// lets a bouncy ball bounce on a default, non-bouncy ground).
#include "world/world.h"

#include <algorithm>
#include <cmath>
#include <numeric>

namespace simbake {

namespace {

double combine_friction(double a, double b) { return std::sqrt(a * b); }
double combine_restitution(double a, double b) { return std::max(a, b); }

}  // namespace

bool World::moving_kinematic(int i) const {
  return defs_[i].kinematic && (states_[i].v != Vec3::Zero() || spin_[i] != Vec3::Zero());
}

void World::compute_boxes(double dt) {
  for (int i = 0; i < body_count(); ++i) {
    const RigidBodyState& s = states_[i];
    const bool still = asleep_[i];
    const Vec3 gravity = (defs_[i].kinematic || still) ? Vec3::Zero() : settings_.gravity;
    const Vec3 v = still ? Vec3::Zero() : s.v;
    const Vec3 to = s.x + dt * (v + dt * gravity);
    const double margin = 0.5 * dt * (v.norm() + dt * gravity.norm()) + 1e-4;
    Box3 box(s.x.cwiseMin(to), s.x.cwiseMax(to));
    box.min().array() -= defs_[i].bounding_radius + margin;
    box.max().array() += defs_[i].bounding_radius + margin;
    boxes_[i] = box;
  }
}

void World::broad_phase(double dt) {
  compute_boxes(dt);
  std::vector<std::pair<int, int>>& overlaps = overlap_scratch_;
  overlapping_pairs(boxes_, grid_, overlaps);
  // wake every sleeping island an awake body or a moving kinematic body touches; a woken
  // island may touch further sleeping islands, hence the loop
  for (bool woke = true; woke;) {
    woke = false;
    for (const auto& [a, b] : overlaps) {
      if (asleep_[a] == asleep_[b]) continue;
      const int sleeper = asleep_[a] ? a : b, other = asleep_[a] ? b : a;
      if (defs_[other].kinematic && !moving_kinematic(other)) continue;
      if (!touching(other, sleeper, dt)) continue;
      wake_island(sleeper);
      woke = true;
    }
    if (woke) compute_boxes(dt);
  }
  pairs_.clear();
  for (const auto& [a, b] : overlaps) {
    if (defs_[a].kinematic && defs_[b].kinematic) continue;
    if (asleep_[a] || asleep_[b]) continue;  // asleep, or asleep against a body not touching it
    pairs_.push_back({a, b, combine_friction(defs_[a].friction, defs_[b].friction),
                      combine_restitution(defs_[a].restitution, defs_[b].restitution)});
  }
  if (ground_) {
    for (int a = 0; a < body_count(); ++a) {
      if (defs_[a].kinematic || asleep_[a] || boxes_[a].min().y() > ground_->height) continue;
      pairs_.push_back({a, kGround, combine_friction(defs_[a].friction, ground_->friction),
                        combine_restitution(defs_[a].restitution, ground_->restitution)});
    }
  }
}

// Does awake body `mover`, advanced over the step with gravity, touch sleeping body `sleeper`?
bool World::touching(int mover, int sleeper, double dt) const {
  RigidBodyState moved = states_[mover];
  if (defs_[mover].kinematic) {
    moved.x += dt * moved.v;
    moved.q = prescribed_rotation(moved.q, spin_[mover], dt);
  } else {
    moved.x += dt * (moved.v + dt * settings_.gravity);
    moved.q = free_rotation(defs_[mover], moved.q, moved.l, dt);
  }
  // a body lies within its bounding sphere: samples outside the other's cannot be inside it
  const Vec3 centres[2] = {moved.x, states_[sleeper].x};
  const double reach = defs_[mover].bounding_radius + defs_[sleeper].bounding_radius;
  if ((centres[0] - centres[1]).squaredNorm() > reach * reach) return false;
  const Pose poses[2] = {mesh_pose(defs_[mover], moved), mesh_pose(defs_[sleeper], states_[sleeper])};
  const int bodies[2] = {mover, sleeper};
  for (int k = 0; k < 2; ++k) {
    const RigidBodyDef& inside = defs_[bodies[1 - k]];
    if (!inside.shape) continue;
    const Points& samples = defs_[bodies[k]].samples;
    const Vec3 centre_inside = poses[k].apply_inverse(centres[1 - k]);
    const double radius = inside.bounding_radius * inside.bounding_radius;
    const std::vector<SampleBlock>& blocks = defs_[bodies[k]].sample_blocks;
    const double slackened = SampleBlock::slackened(centre_inside, inside.bounding_radius);
    for (std::size_t block = 0; block < blocks.size(); ++block) {
      if (!blocks[block].may_reach(centre_inside, slackened)) continue;
      const Eigen::Index first = static_cast<Eigen::Index>(block) * SampleBlock::kSize;
      const Eigen::Index end = std::min<Eigen::Index>(first + SampleBlock::kSize, samples.rows());
      for (Eigen::Index s = first; s < end; ++s) {
        if ((samples.row(s).transpose() - centre_inside).squaredNorm() > radius) continue;
        const Vec3 p = poses[1 - k].apply_inverse(poses[k].apply(samples.row(s).transpose()));
        if (inside.shape->bounds().contains(p) && inside.shape->phi(p) < 0.0) return true;
      }
    }
  }
  return false;
}

// ---------------------------------------------------------------------------------------
// Sleeping

int World::find_island(int i) {
  while (island_[i] != i) i = island_[i] = island_[island_[i]];
  return i;
}

void World::wake_island(int i) {
  const int root = island_[i];
  for (int j = 0; j < body_count(); ++j) {
    if (asleep_[j] && island_[j] == root) {
      asleep_[j] = 0;
      rest_time_[j] = 0.0;
    }
  }
}

void World::update_sleeping(double dt) {
  if (settings_.sleep_time <= 0.0) return;
  const int n = body_count();
  // islands of awake dynamic bodies through this step's contacts (union-find, smaller root wins)
  for (int i = 0; i < n; ++i) {
    if (!asleep_[i]) island_[i] = i;
  }
  for (const ContactPoint& contact : contacts_) {
    const int a = contact.point.a, b = contact.point.b;
    if (contact.apart || b == kGround || defs_[a].kinematic || defs_[b].kinematic) continue;
    const int ra = find_island(a), rb = find_island(b);
    if (ra != rb) island_[std::max(ra, rb)] = std::min(ra, rb);
  }
  // rest time of each awake body; an island is ready when all of its bodies are
  std::vector<char> ready(n, 1);
  const double allowed = 0.5 * settings_.sleep_speed * settings_.sleep_time;  // (m)
  for (int i = 0; i < n; ++i) {
    if (defs_[i].kinematic || asleep_[i]) continue;
    const RigidBodyState& s = states_[i];
    const double speed = s.v.norm() + angular_velocity(defs_[i], s).norm() * defs_[i].bounding_radius;
    const double strayed = (s.x - rest_pose_[i].x).norm() +
                           s.q.angularDistance(rest_pose_[i].q) * defs_[i].bounding_radius;
    if ((speed >= settings_.sleep_speed && strayed > allowed) || rest_time_[i] == 0.0) {
      rest_time_[i] = dt;
      rest_pose_[i] = s;
    } else {
      rest_time_[i] += dt;
    }
    if (rest_time_[i] < settings_.sleep_time) ready[find_island(i)] = 0;
  }
  // still pushing out of a deep overlap (deeper than ten times the slop) keeps an island awake,
  // as does touching a moving kinematic body
  for (const ContactPoint& c : contacts_) {
    if (-c.point.phi <= 10.0 * settings_.penetration_slop) continue;
    for (int i : {c.point.a, c.point.b}) {
      if (i != kGround && !defs_[i].kinematic) ready[find_island(i)] = 0;
    }
  }
  for (const ContactPoint& c : contacts_) {
    if (moving_kinematic(c.point.a) && c.point.b != kGround) ready[find_island(c.point.b)] = 0;
    if (c.point.b != kGround && moving_kinematic(c.point.b)) ready[find_island(c.point.a)] = 0;
  }
  for (int i = 0; i < n; ++i) {
    if (defs_[i].kinematic || asleep_[i]) continue;
    island_[i] = find_island(i);
    if (!ready[island_[i]]) continue;
    asleep_[i] = 1;
    states_[i].v = Vec3::Zero();
    states_[i].l = Vec3::Zero();
  }
}

int World::sleeping_count() const {
  return static_cast<int>(std::count(asleep_.begin(), asleep_.end(), 1));
}

}  // namespace simbake
