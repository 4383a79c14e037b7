#include "world/statistics.h"

#include "rigid/box_contact.h"
#include "rigid/narrow_phase.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <utility>

namespace simbake {

namespace {

// Deepest sample of either body of the pair inside the other (or the ground), now (m, >= 0)
double pair_penetration(const RigidModel& model, const RigidData& data, const BodyPair& pair) {
  // two boxes: the separating axes' depth alone, which no point of either box inside the other
  // can exceed (moving a point at depth d out of a convex body takes a translation >= d)
  OrientedBox box_a, box_b;
  const bool boxes = pair.b != kGround &&
                     body_box(model, pair.a, body_mesh_pose(model, data, pair.a), box_a) &&
                     body_box(model, pair.b, body_mesh_pose(model, data, pair.b), box_b);
  if (boxes) return box_overlap_depth(box_a, box_b);
  double deepest = 0.0;
  for (const auto& [a, b] : {std::pair{pair.a, pair.b}, std::pair{pair.b, pair.a}}) {
    if (a == kGround || (b != kGround && !model.defs[b].shape)) continue;
    const Pose pose_a = body_mesh_pose(model, data, a);
    const Pose pose_b = b == kGround ? Pose() : body_mesh_pose(model, data, b);
    const Box3 bounds = b == kGround ? Box3() : model.defs[b].shape->bounds();
    const Points& samples = model.defs[a].samples;
    for (Eigen::Index s = 0; s < samples.rows(); ++s) {
      const Vec3 x = pose_a.apply(samples.row(s).transpose());
      if (b == kGround) {
        deepest = std::max(deepest, model.ground->height - x.y());
        continue;
      }
      const Vec3 p = pose_b.apply_inverse(x);
      if (bounds.contains(p)) deepest = std::max(deepest, -model.defs[b].shape->phi(p));
    }
  }
  return deepest;
}

// Deepest cloth vertex inside a body or the ground, past the surface itself (m, >= 0)
double cloth_penetration(const RigidModel& model, const RigidData& data, const std::vector<SteppedCloth>& cloths) {
  double deepest = 0.0;
  for (const SteppedCloth& stepped : cloths) {
    const Cloth& cloth = stepped.cloth;
    const Points& x = cloth.positions();
    for (int k = 0; k < cloth.vertex_count(); ++k) {
      const Vec3 xk = x.row(k).transpose();
      if (model.ground) deepest = std::max(deepest, model.ground->height - xk.y());
      for (int b = 0; b < model.body_count(); ++b) {
        if (!model.defs[b].shape || (xk - data.x[b]).norm() > model.defs[b].bounding_radius) continue;
        deepest = std::max(deepest, -model.defs[b].shape->phi(body_mesh_pose(model, data, b).apply_inverse(xk)));
      }
    }
  }
  return deepest;
}

}  // namespace

double max_penetration(const RigidModel& model, const RigidData& data, const std::vector<BodyPair>& pairs) {
  // the pairs the last broad phase kept are the only ones that can touch (the boxes hold
  // the whole step); every sample is tested in both directions at the current poses. Pairs
  // in parallel: the maximum is the same in any order
  return tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, pairs.size()), 0.0,
      [&](const tbb::blocked_range<std::size_t>& range, double deepest) {
        for (std::size_t k = range.begin(); k < range.end(); ++k) {
          deepest = std::max(deepest, pair_penetration(model, data, pairs[k]));
        }
        return deepest;
      },
      [](double l, double r) { return std::max(l, r); });
}

void gather_statistics(const RigidModel& model, const RigidData& data, const std::vector<SteppedCloth>& cloths,
                       const WorldSettings& settings, StepStatistics& stats) {
  double kinetic = 0.0, potential = 0.0;
  for (int i = 0; i < model.body_count(); ++i) {
    if (model.defs[i].kinematic) continue;
    kinetic += kinetic_energy(model.defs[i], data.v[i], data.q[i], data.l[i]);
    potential -= settings.gravity.dot(data.x[i]) / model.defs[i].inverse_mass;
  }
  double elastic = 0.0, strain = 0.0;
  long long iterations = 0;
  double solver_seconds = 0.0;
  for (const SteppedCloth& stepped : cloths) {
    const Cloth& c = stepped.cloth;
    iterations += c.solver_iterations();
    solver_seconds += c.solver_seconds();
    kinetic += c.kinetic_energy();
    potential += c.potential_energy(settings.gravity);
    elastic += c.elastic_energy();
    strain = std::max(strain, c.max_strain());
  }
  stats.kinetic_energy = kinetic;
  stats.potential_energy = potential;
  stats.elastic_energy = elastic;
  stats.max_cloth_strain = strain;
  stats.cloth_solver_iterations = iterations;
  stats.cloth_solver_seconds = solver_seconds;
}

void measure_penetrations(const RigidModel& model, const RigidData& data, const std::vector<BodyPair>& pairs,
                          const std::vector<SteppedCloth>& cloths, StepStatistics& stats) {
  stats.max_penetration = max_penetration(model, data, pairs);
  stats.cloth_penetration = cloth_penetration(model, data, cloths);
}

bool state_finite(const RigidData& data, const std::vector<SteppedCloth>& cloths) {
  for (std::size_t i = 0; i < data.x.size(); ++i) {
    if (!(data.x[i].allFinite() && data.v[i].allFinite() && data.l[i].allFinite() && data.q[i].coeffs().allFinite())) {
      return false;
    }
  }
  for (const SteppedCloth& stepped : cloths) {
    const Cloth& c = stepped.cloth;
    if (!(c.positions().allFinite() && c.velocities().allFinite())) return false;
  }
  return true;
}

}  // namespace simbake
