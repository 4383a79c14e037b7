#include "world/quality.h"

#include "geometry/triangle_intersection.h"
#include "rigid/box_contact.h"
#include "rigid/collision_filter.h"

#include <algorithm>
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

}  // namespace

PenetrationFigure body_penetration(const World& w) {
  const int n = w.body_count();
  PenetrationFigure deepest;
  std::vector<Pose> poses(n);
  for (int i = 0; i < n; ++i) poses[i] = w.body_mesh_pose(i);
  // dynamic bodies against the ground
  if (w.ground()) {
    const double height = w.ground()->height;
    for (int a = 0; a < n; ++a) {
      if (w.body_def(a).kinematic) continue;
      const Points& samples = w.body_def(a).samples;
      for (Eigen::Index s = 0; s < samples.rows(); ++s) {
        offer(deepest, height - poses[a].apply(samples.row(s).transpose()).y(), a, -1);
      }
    }
  }
  // pairs whose bounding spheres meet (sweep along x), each body's samples in the other
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
      // a dynamic body's samples first, so that on a tie it is named as the one inside
      const bool i_first = !w.body_def(i).kinematic;
      samples_inside(w, i_first ? i : j, i_first ? j : i, poses, deepest);
      samples_inside(w, i_first ? j : i, i_first ? i : j, poses, deepest);
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

FrameQuality measure_quality(const World& w) {
  FrameQuality quality;
  quality.body_penetration = body_penetration(w);
  for (int c = 0; c < w.cloth_count(); ++c) quality.cloths.push_back(cloth_quality(w, c));
  return quality;
}

}  // namespace simbake
