#include "world/quality.h"

#include "geometry/triangle_intersection.h"
#include "rigid/box_contact.h"
#include "rigid/collision_filter.h"
#include "levelset/signed_distance.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numeric>
#include <stdexcept>
#include <utility>

namespace simbake {

namespace {

// Keeps the deepest of the depths offered to it (the first one on a tie, so the order of
// the loops decides and the result is the same on every run)
void offer(PenetrationFigure& deepest, double depth, int a, int b) {
  if (depth > deepest.depth) deepest = PenetrationFigure{depth, a, b};
}

// Samples of body a inside body b, at the current poses
void samples_inside(const World& w, int a, int b, const std::vector<Pose>& poses, PenetrationFigure& deepest) {
  const RigidBodyDef& def_b = w.body_def(b);
  if (!def_b.shape) return;
  const Box3 bounds = def_b.shape->bounds();
  const Points& samples = w.body_def(a).samples;
  for (Eigen::Index s = 0; s < samples.rows(); ++s) {
    const Vec3 p = poses[b].apply_inverse(poses[a].apply(samples.row(s).transpose()));
    if (bounds.contains(p)) offer(deepest, -def_b.shape->phi(p), a, b);
  }
  // two boxes: also edges crossing between the samples (the separating axes' depth)
  OrientedBox box_a, box_b;
  if (oriented_box(w.body_def(a).shape.get(), poses[a], box_a) && oriented_box(def_b.shape.get(), poses[b], box_b)) {
    offer(deepest, box_overlap_depth(box_a, box_b), a, b);
  }
}

// Every candidate of the body figure, in the order the figure is defined by: each dynamic
// body against the ground, then the pairs whose bounding spheres meet, in a sweep along x
// (the first of a pair a dynamic body, so that on a tie it is named as the one inside)
struct Candidate {
  int a = -1, b = -1;   // b = -1: the ground
  double bound = 0.0;   // no depth of this candidate exceeds it (m)
};

// Where one body is now, and what bounds its samples' depths (its extent)
struct BodyReach {
  Pose pose;
  bool finite = true;
  OrientedBox box;  // (extent.is_box)
  BodyExtent extent;
};

// Depths and bounds are both computed in floating point from coordinates of a few metres:
// a bound this much above its exact value (m) stays above every depth it bounds
constexpr double kBoundSlack = 1e-6;

BodyReach body_reach(const World& w, int i, const BodyExtent& extent) {
  BodyReach r;
  r.pose = w.body_mesh_pose(i);
  r.finite = r.pose.rotation.allFinite() && r.pose.translation.allFinite();
  r.extent = extent;
  if (extent.is_box) r.box = {r.pose.translation, r.pose.rotation, extent.half};
  return r;
}

// The deepest any sample of body a can be under the ground: its box's lowest corner, or its
// mesh origin less the samples' reach
double ground_bound(double height, const BodyReach& a) {
  if (!a.finite) return INFINITY;
  if (a.extent.samples_in_box) {
    const Mat3& R = a.box.rotation;
    const double reach = a.box.half.dot(Vec3(std::abs(R(1, 0)), std::abs(R(1, 1)), std::abs(R(1, 2))));
    return height - (a.box.center.y() - reach) + kBoundSlack;
  }
  return height - (a.pose.translation.y() - a.extent.samples) + kBoundSlack;
}

// The deepest any sample of either body can be inside the other (and, two boxes, their
// overlap). A point of one box inside another is no deeper than the boxes' overlap along any
// axis; a point within `samples` of one mesh origin and inside a solid that lies within
// `solid` of the other origin is no deeper than samples + solid - the origins' distance.
double pair_bound(const BodyReach& a, const BodyReach& b) {
  if (!a.finite || !b.finite) return INFINITY;
  const BodyExtent &ea = a.extent, &eb = b.extent;
  const double overlap = ea.is_box && eb.is_box ? std::max(box_face_overlap(a.box, b.box), 0.0) : 0.0;
  if (ea.samples_in_box && eb.samples_in_box) return overlap + kBoundSlack;
  const double apart = (a.pose.translation - b.pose.translation).norm();
  return std::max(overlap, std::max(ea.samples + eb.solid, eb.samples + ea.solid) - apart) + kBoundSlack;
}

// The candidates of the body figure, in its order, with their bounds
std::vector<Candidate> candidates(const World& w, const std::vector<BodyReach>& reach) {
  const int n = w.body_count();
  std::vector<Candidate> out;
  if (w.ground()) {
    for (int a = 0; a < n; ++a) {
      if (!w.body_def(a).kinematic) out.push_back({a, -1, ground_bound(w.ground()->height, reach[a])});
    }
  }
  std::vector<int> order(n);
  std::iota(order.begin(), order.end(), 0);
  const auto low = [&w](int i) { return w.rigid_data().x[i].x() - w.body_def(i).bounding_radius; };
  std::stable_sort(order.begin(), order.end(), [&](int i, int j) { return low(i) < low(j); });
  for (int p = 0; p < n; ++p) {
    const int i = order[p];
    const Vec3& xi = w.rigid_data().x[i];
    const double ri = w.body_def(i).bounding_radius;
    for (int q = p + 1; q < n && low(order[q]) <= xi.x() + ri; ++q) {
      const int j = order[q];
      if (w.body_def(i).kinematic && w.body_def(j).kinematic) continue;
      if ((w.rigid_data().x[j] - xi).norm() > ri + w.body_def(j).bounding_radius) continue;
      // (a pair kept from colliding, jointed or filtered, may overlap)
      if (w.rigid_model().filters_collisions() && collision_filtered(w.rigid_model(), w.rigid_data(), i, j)) continue;
      const bool i_first = !w.body_def(i).kinematic;
      out.push_back({i_first ? i : j, i_first ? j : i, pair_bound(reach[i], reach[j])});
    }
  }
  return out;
}

// The deepest of one candidate's depths, first on a tie, as the figure's loops offer them
PenetrationFigure candidate_depth(const World& w, const Candidate& c, const std::vector<Pose>& poses) {
  PenetrationFigure deepest;
  if (c.b < 0) {
    const double height = w.ground()->height;
    const Points& samples = w.body_def(c.a).samples;
    for (Eigen::Index s = 0; s < samples.rows(); ++s) {
      offer(deepest, height - poses[c.a].apply(samples.row(s).transpose()).y(), c.a, -1);
    }
    return deepest;
  }
  samples_inside(w, c.a, c.b, poses, deepest);
  samples_inside(w, c.b, c.a, poses, deepest);
  return deepest;
}

}  // namespace

BodyExtent body_extent(const RigidBodyDef& def) {
  BodyExtent e;
  e.shape = def.shape.get();
  e.samples_at = def.samples.data();
  e.sample_count = def.samples.rows();
  for (Eigen::Index s = 0; s < def.samples.rows(); ++s) e.samples = std::max(e.samples, def.samples.row(s).norm());
  OrientedBox box;
  if (const auto* sphere = dynamic_cast<const SphereDistance*>(def.shape.get())) {
    e.solid = -sphere->phi(Vec3::Zero());
  } else if (oriented_box(def.shape.get(), Pose{}, box)) {
    e.half = box.half;
    e.solid = box.half.norm();
    e.is_box = true;
    e.samples_in_box = true;
    for (Eigen::Index s = 0; s < def.samples.rows(); ++s) {
      e.samples_in_box = e.samples_in_box && (def.samples.row(s).transpose().cwiseAbs() - box.half).maxCoeff() <= 0.0;
    }
  } else if (!def.shape) {
    e.solid = 0.0;  // (nothing is inside a body without a shape)
  }
  return e;
}

PenetrationFigure body_penetration(const World& w) {
  std::vector<BodyExtent> extents(w.body_count());
  for (int i = 0; i < w.body_count(); ++i) extents[i] = body_extent(w.body_def(i));
  return body_penetration(w, extents);
}

PenetrationFigure body_penetration_every_sample(const World& w) {
  const int n = w.body_count();
  std::vector<BodyReach> reach(n);
  std::vector<Pose> poses(n);
  for (int i = 0; i < n; ++i) poses[i] = w.body_mesh_pose(i);
  PenetrationFigure deepest;
  for (const Candidate& c : candidates(w, reach)) {
    const PenetrationFigure d = candidate_depth(w, c, poses);
    offer(deepest, d.depth, d.a, d.b);
  }
  return deepest;
}

// The candidates deepest bound first: once a bound is below the deepest depth found, no
// later candidate can be deeper (nor tie: a tie goes to the candidate first in the figure's
// order, so a candidate whose bound equals the deepest is still measured)
PenetrationFigure body_penetration(const World& w, const std::vector<BodyExtent>& extents) {
  const int n = w.body_count();
  std::vector<BodyReach> reach(n);
  std::vector<Pose> poses(n);
  for (int i = 0; i < n; ++i) {
    reach[i] = body_reach(w, i, extents[i]);
    poses[i] = reach[i].pose;
  }
  const std::vector<Candidate> all = candidates(w, reach);
  std::vector<int> order(all.size());
  std::iota(order.begin(), order.end(), 0);
  const auto bound = [&all](int k) { return std::isnan(all[k].bound) ? INFINITY : all[k].bound; };
  std::stable_sort(order.begin(), order.end(), [&](int i, int j) { return bound(i) > bound(j); });
  PenetrationFigure deepest;
  int first = -1;  // the candidate that gave `deepest`
  for (int k : order) {
    if (!(bound(k) > 0.0) || bound(k) < deepest.depth) break;
    const PenetrationFigure d = candidate_depth(w, all[k], poses);
    if (d.depth > deepest.depth || (d.a >= 0 && d.depth == deepest.depth && k < first)) {
      deepest = d;
      first = k;
    }
  }
  return deepest;
}

ClothQuality cloth_quality(const World& w, int c) {
  const Cloth& cloth = w.cloth(c);
  const Points& x = cloth.positions();
  ClothQuality q;
  q.max_strain = cloth.max_strain();
  try {
    q.self_intersections =
        static_cast<long long>(intersecting_triangle_pairs(x, cloth.triangles(), kPairTestBudget).size());
  } catch (const std::length_error&) {
    q.self_intersections = -1;  // (not counted: the QA says so)
  }

  // bodies whose bounding spheres reach the cloth's box, with their poses
  Box3 box;
  for (Eigen::Index k = 0; k < x.rows(); ++k) box.extend(x.row(k).transpose());
  std::vector<int> near;
  std::vector<Pose> poses;
  for (int b = 0; b < w.body_count(); ++b) {
    const Vec3& center = w.rigid_data().x[b];
    if (!w.body_def(b).shape || box.isEmpty()) continue;
    if ((center.cwiseMax(box.min()).cwiseMin(box.max()) - center).norm() > w.body_def(b).bounding_radius) continue;
    near.push_back(b);
    poses.push_back(w.body_mesh_pose(b));
  }
  // how deep a point is inside the ground or a body, past its surface
  const auto probe = [&](const Vec3& p, PenetrationFigure& deepest) {
    if (w.ground()) offer(deepest, w.ground()->height - p.y(), c, -1);
    for (size_t k = 0; k < near.size(); ++k) {
      const int b = near[k];
      if ((p - w.rigid_data().x[b]).norm() > w.body_def(b).bounding_radius) continue;
      offer(deepest, -w.body_def(b).shape->phi(poses[k].apply_inverse(p)), c, b);
    }
  };
  for (Eigen::Index k = 0; k < x.rows(); ++k) probe(x.row(k).transpose(), q.vertex_penetration);
  for (const auto& [i, j] : w.cloth_edges(c)) {
    const Vec3 a = x.row(i).transpose(), b = x.row(j).transpose();
    // eighths: finer than the cloth's own edge contacts (quarters), so the figure judges them
    for (int k = 1; k < 8; ++k) probe(a + (k / 8.0) * (b - a), q.edge_penetration);
  }
  return q;
}

bool QualityMeter::unchanged(const World& w) const {
  const int n = w.body_count();
  if (!measured_ || static_cast<int>(poses_.size()) != 7 * n) return false;
  for (int i = 0; i < n; ++i) {
    const RigidBodyDef& def = w.body_def(i);
    if (shapes_[2 * i] != def.shape.get() || shapes_[2 * i + 1] != def.samples.data()) return false;
    const Vec3& x = w.rigid_data().x[i];
    const Quat& q = w.rigid_data().q[i];
    const double now[7] = {x.x(), x.y(), x.z(), q.w(), q.x(), q.y(), q.z()};
    if (std::memcmp(now, &poses_[7 * i], sizeof now) != 0) return false;
  }
  const double ground = w.ground() ? w.ground()->height : NAN;
  return std::memcmp(&ground, &ground_, sizeof ground) == 0 && w.rigid_data().joints.enabled == joints_enabled_;
}

void QualityMeter::remember(const World& w) {
  const int n = w.body_count();
  poses_.resize(7 * n);
  shapes_.resize(2 * n);
  for (int i = 0; i < n; ++i) {
    const Vec3& x = w.rigid_data().x[i];
    const Quat& q = w.rigid_data().q[i];
    const double now[7] = {x.x(), x.y(), x.z(), q.w(), q.x(), q.y(), q.z()};
    std::memcpy(&poses_[7 * i], now, sizeof now);
    shapes_[2 * i] = w.body_def(i).shape.get();
    shapes_[2 * i + 1] = w.body_def(i).samples.data();
  }
  joints_enabled_ = w.rigid_data().joints.enabled;
  ground_ = w.ground() ? w.ground()->height : NAN;
  measured_ = true;
}

FrameQuality QualityMeter::measure(const World& w) {
  if (!unchanged(w)) {
    extents_.resize(w.body_count());
    for (int i = 0; i < w.body_count(); ++i) {
      const RigidBodyDef& def = w.body_def(i);
      const BodyExtent& e = extents_[i];
      if (e.shape != def.shape.get() || e.samples_at != def.samples.data() || e.sample_count != def.samples.rows()) {
        extents_[i] = body_extent(def);
      }
    }
    body_ = body_penetration(w, extents_);
    remember(w);
  }
  FrameQuality quality;
  quality.body_penetration = body_;
  for (int c = 0; c < w.cloth_count(); ++c) quality.cloths.push_back(cloth_quality(w, c));
  return quality;
}

FrameQuality measure_quality(const World& w) {
  FrameQuality quality;
  quality.body_penetration = body_penetration(w);
  for (int c = 0; c < w.cloth_count(); ++c) quality.cloths.push_back(cloth_quality(w, c));
  return quality;
}

}  // namespace simbake
