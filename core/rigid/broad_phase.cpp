// The broad phase: what lets the cost of a step follow the bodies that move.
//
// Each body's box holds its bounding sphere at the start of the step and at the candidate
// with gravity, grown by a margin for what impulses may add during the step. Boxes are binned
// into a uniform grid (see overlapping_pairs), so the cost is O(n + pairs) rather than
// O(n^2). The pair list is sorted by index, so the order in which later stages see pairs
// depends only on the scene. A sleeping island (rigid/sleeping.h) wakes when an awake dynamic
// body or a moving kinematic body touches it: a sample of one inside the other, the awake
// body taken where it will be at the end of the step. Mere box overlap does not wake it, so a
// settled part of a pile sleeps beside a part still sliding.
//
// Materials. A pair's friction is the geometric mean sqrt(mu_a mu_b) and its restitution the
// larger of the two (both symmetric and both give back the common value when equal; max
// lets a bouncy ball bounce on a default, non-bouncy ground).
#include "rigid/broad_phase.h"

#include "rigid/collision_filter.h"
#include "rigid/sleeping.h"

#include <algorithm>
#include <cmath>

namespace simbake {

double combine_friction(double a, double b) { return std::sqrt(a * b); }
double combine_restitution(double a, double b) { return std::max(a, b); }

namespace {

void compute_boxes(const RigidModel& model, const RigidData& data, RigidScratch& scratch, const WorldSettings& settings,
                   double dt) {
  for (int i = 0; i < model.body_count(); ++i) {
    const Vec3& x = data.x[i];
    const bool still = data.asleep[i];
    const Vec3 gravity = (model.defs[i].kinematic || still) ? Vec3::Zero() : settings.gravity;
    const Vec3 v = still ? Vec3::Zero() : data.v[i];
    const Vec3 to = x + dt * (v + dt * gravity);
    const double margin = 0.5 * dt * (v.norm() + dt * gravity.norm()) + 1e-4;
    Box3 box(x.cwiseMin(to), x.cwiseMax(to));
    box.min().array() -= model.defs[i].bounding_radius + margin;
    box.max().array() += model.defs[i].bounding_radius + margin;
    scratch.boxes[i] = box;
  }
}

// Does awake body `mover`, advanced over the step with gravity, touch sleeping body `sleeper`?
bool touching(const RigidModel& model, const RigidData& data, const WorldSettings& settings, int mover, int sleeper,
              double dt) {
  Vec3 moved_x = data.x[mover];
  Quat moved_q = data.q[mover];
  if (model.defs[mover].kinematic) {
    moved_x += dt * data.v[mover];
    moved_q = prescribed_rotation(moved_q, data.spin[mover], dt);
  } else {
    moved_x += dt * (data.v[mover] + dt * settings.gravity);
    moved_q = free_rotation(model.defs[mover], moved_q, data.l[mover], dt);
  }
  // a body lies within its bounding sphere: samples outside the other's cannot be inside it
  const Vec3 centres[2] = {moved_x, data.x[sleeper]};
  const double reach = model.defs[mover].bounding_radius + model.defs[sleeper].bounding_radius;
  if ((centres[0] - centres[1]).squaredNorm() > reach * reach) return false;
  const Pose poses[2] = {mesh_pose(model.defs[mover], moved_x, moved_q), body_mesh_pose(model, data, sleeper)};
  const int bodies[2] = {mover, sleeper};
  for (int k = 0; k < 2; ++k) {
    const RigidBodyDef& inside = model.defs[bodies[1 - k]];
    if (!inside.shape) continue;
    const Points& samples = model.defs[bodies[k]].samples;
    const Vec3 centre_inside = poses[k].apply_inverse(centres[1 - k]);
    const double radius = inside.bounding_radius * inside.bounding_radius;
    const std::vector<SampleBlock>& blocks = model.defs[bodies[k]].sample_blocks;
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

}  // namespace

void broad_phase(const RigidModel& model, RigidData& data, RigidScratch& scratch, const WorldSettings& settings,
                 double dt) {
  compute_boxes(model, data, scratch, settings, dt);
  std::vector<std::pair<int, int>>& overlaps = scratch.overlaps;
  overlapping_pairs(scratch.boxes, scratch.grid, overlaps);
  // wake every sleeping island an awake body or a moving kinematic body touches; a woken
  // island may touch further sleeping islands, hence the loop
  for (bool woke = true; woke;) {
    woke = false;
    for (const auto& [a, b] : overlaps) {
      if (data.asleep[a] == data.asleep[b]) continue;
      const int sleeper = data.asleep[a] ? a : b, other = data.asleep[a] ? b : a;
      if (model.defs[other].kinematic && !moving_kinematic(model, data, other)) continue;
      if (!touching(model, data, settings, other, sleeper, dt)) continue;
      wake_island(model, data, sleeper);
      woke = true;
    }
    if (woke) compute_boxes(model, data, scratch, settings, dt);
  }
  scratch.pairs.clear();
  for (const auto& [a, b] : overlaps) {
    if (model.defs[a].kinematic && model.defs[b].kinematic) continue;
    if (data.asleep[a] || data.asleep[b]) continue;  // asleep, or asleep against a body not touching it
    if (model.filters_collisions() && collision_filtered(model, data, a, b)) continue;
    scratch.pairs.push_back({a, b, combine_friction(model.defs[a].friction, model.defs[b].friction),
                             combine_restitution(model.defs[a].restitution, model.defs[b].restitution)});
  }
  if (model.ground) {
    for (int a = 0; a < model.body_count(); ++a) {
      if (model.defs[a].kinematic || data.asleep[a] || scratch.boxes[a].min().y() > model.ground->height) continue;
      scratch.pairs.push_back({a, kGround, combine_friction(model.defs[a].friction, model.ground->friction),
                               combine_restitution(model.defs[a].restitution, model.ground->restitution)});
    }
  }
}

}  // namespace simbake
