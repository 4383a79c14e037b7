#include "contact/cloth_obstacles.h"

#include "levelset/signed_distance.h"

#include <algorithm>

namespace simbake {

bool ClothObstacles::select(const ContactBodies& bodies) {
  std::vector<int> chosen;
  for (int b = 0; b < bodies.count(); ++b) {
    const ContactBody& body = bodies.body(b);
    const bool box = dynamic_cast<const BoxDistance*>(body.shape) != nullptr;
    const bool mesh = body.mesh && body.mesh->triangles.rows() > 0;
    if (body.kinematic && body.shape && (box || mesh)) chosen.push_back(b);
  }
  if (chosen == body_) return false;
  body_ = chosen;
  mesh_.clear();
  for (int b : body_) {
    const ContactBody& body = bodies.body(b);
    if (const auto* box = dynamic_cast<const BoxDistance*>(body.shape)) {
      mesh_.push_back(make_box_mesh(2.0 * box->half(), 1));
    } else {
      mesh_.push_back(*body.mesh);
    }
  }
  return true;
}

void ClothObstacles::begin_step(const Cloth& cloth, const ContactBodies& bodies, const Eigen::VectorXd& inverse_mass,
                                double dt, double give) {
  cloth_vertices_ = cloth.vertex_count();
  Eigen::Index n = cloth_vertices_;
  for (const TriangleMesh& m : mesh_) n += m.vertices.rows();
  x_.resize(n, 3);
  v_.resize(n, 3);
  inverse_mass_.setZero(n);
  x_.topRows(cloth_vertices_) = cloth.positions();
  inverse_mass_.head(cloth_vertices_) = inverse_mass;
  support_.assign(n, Vec3::Zero());
  motion_.resize(body_.size());
  Eigen::Index row = cloth_vertices_;
  for (size_t o = 0; o < body_.size(); ++o) {
    const ContactBody& body = bodies.body(body_[o]);
    if (body.surface) {  // a deforming surface: each vertex on its own line over the frame
      row = deforming_rows(*body.surface, body.surface_start, body.surface_end, dt, row, motion_[o]);
      continue;
    }
    const Pose& from = body.start_pose;
    const Pose& to = body.pose;
    for (Eigen::Index k = 0; k < mesh_[o].vertices.rows(); ++k, ++row) {
      const Vec3 p = mesh_[o].vertices.row(k).transpose();
      const Vec3 start = from.apply(p);
      x_.row(row) = start.transpose();
      v_.row(row) = ((to.apply(p) - start) / dt).transpose();
    }
    const Mat3 turn = to.rotation * from.rotation.transpose();
    motion_[o].A = (turn - Mat3::Identity()) / dt;
    motion_[o].c = (to.translation - turn * from.translation) / dt;
  }
  // the cloth's vertices no obstacle keeps out (yielding()): inside one at its start pose, or
  // near one when the cloth gives
  yielding_.assign(n, 0);
  any_yielding_ = false;
  for (size_t o = 0; o < body_.size(); ++o) {
    const ContactBody& body = bodies.body(body_[o]);
    Box3 near = body.shape->bounds();
    near.min().array() -= give;
    near.max().array() += give;
    for (int k = 0; k < cloth_vertices_; ++k) {
      if (!(inverse_mass_[k] > 0.0)) continue;  // pinned: never moves (the flag's pins are inside its pole)
      const Vec3 p = body.start_pose.apply_inverse(Vec3(x_.row(k).transpose()));
      if (!near.contains(p)) continue;
      const double phi = body.shape->phi(p);
      if (phi < give) yielding_[k] = any_yielding_ = true;  // (inside: phi < 0 <= give)
    }
  }
}

// A deforming surface's vertices at the step's start (blend s0) with the velocities that
// take them to where they are at its end (s1), from `row` on; its impact zones' motion is the
// affine field nearest the vertices' velocities (DeformingSurface::affine_motion)
Eigen::Index ClothObstacles::deforming_rows(const DeformingSurface& surface, double s0, double s1, double dt,
                                            Eigen::Index row, ObstacleMotion& motion) {
  for (int k = 0; k < surface.vertex_count(); ++k, ++row) {
    const Vec3 start = surface.vertex(k, s0);
    x_.row(row) = start.transpose();
    v_.row(row) = ((surface.vertex(k, s1) - start) / dt).transpose();
  }
  surface.affine_motion(s0, motion.A, motion.c);
  return row;
}

void ClothObstacles::load(const Points& cloth_velocities, const std::vector<Vec3>& cloth_support) {
  v_.topRows(cloth_vertices_) = cloth_velocities;
  std::fill(support_.begin(), support_.begin() + cloth_vertices_, Vec3::Zero());
  std::copy_n(cloth_support.begin(), std::min<size_t>(cloth_support.size(), cloth_vertices_), support_.begin());
}

void ClothObstacles::store(Points& cloth_velocities) const { cloth_velocities = v_.topRows(cloth_vertices_); }

std::vector<char> ClothObstacles::cloth_part(const std::vector<char>& all) const {
  return std::vector<char>(all.begin(), all.begin() + cloth_vertices_);
}

Points ClothObstacles::padded(const Points& cloth_rows) const {
  Points all = Points::Zero(x_.rows(), 3);
  all.topRows(cloth_vertices_) = cloth_rows;
  return all;
}

}  // namespace simbake
