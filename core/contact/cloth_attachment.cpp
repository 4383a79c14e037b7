// Cloth points attached to a body's surface (the interface is in cloth_attachment.h).
//
// Binding, once, where the cloth is when the attachment is made. Each attached vertex p is
// bound to the body's surface point s nearest it, and keeps its offset p - s in the surface's
// own frame, so that nothing moves at the binding (a point on the surface stays on it; one a
// little off it stays that far off, on the same side):
//   - a rigid body (dynamic, keyed or static): its surface and the offset both ride the body's
//     rigid motion, so p is kept in the body's mesh frame, p_b = P0^-1 p (P0 the mesh pose
//     now), and is carried to P(t) p_b;
//   - a deforming surface (contact/deforming_surface.h): s is the nearest point of its mesh,
//     on triangle T with barycentric weights w, and the offset is kept in T's frame
//     F = [e1, n x e1, n] (e1 along T's first edge, n its unit normal): o = F^T (p - s). It is
//     carried to s(t) + F(t) o, s(t) = sum_k w_k v_k(t), as T's vertices move (so it rides the
//     skin, and turns with it).
//
// Carrying, each cloth step over dt. The attached vertices get the velocity that takes them
// from where they are to their carried position at the step's end, (target - x) / dt. The
// cloth's stages treat them as of infinite mass and keep that velocity (ClothDesc::attached):
// the implicit solve sees them at x + dt v, so the cloth hanging from them answers to their
// motion inside the solve, as to a pin's (no strain spike where it hangs), and strain
// limiting, the contacts and self-collision never move them; the impact zones that hold them
// move with the attachment's motion. After the step they are put exactly on their targets
// (the solve's x + dt v differs from them by round-off only).
//
// Reaction, for a dynamic body. What the attachment gives the cloth over a step is measured
// as momentum: the change of the cloth's momentum (and of its angular momentum about the
// body's centre of mass) over the stages through which the attached vertices act on the rest
// (the velocities they are given, the forces and velocity update, strain limiting), less
// what else acts in those stages: gravity on the cloth that hangs from the attachment (its
// free and attached vertices; a pinned vertex's weight is its pin's) and the contacts held in
// the solve. The body takes the opposite: the cloth's weight, its pull and its inertia where
// it hangs, at the next body step (as the cloth's contacts' impulses reach bodies). Total
// momentum of the body and the cloth then changes by gravity and the contacts only. Not
// counted: self-collision's impulses on attached vertices (a fold of the cloth pushed against
// its own attached row) in a step where a pin, an obstacle or a still surface takes part in
// self-collision too (cloth_step.cpp). The reaction comes a step late, so the body must
// outweigh the cloth (check_carrier).
#include "contact/cloth_attachment.h"

#include "geometry/closest_points.h"

#include <Eigen/Eigenvalues>

#include <cstdio>
#include <limits>
#include <stdexcept>
#include <string>

namespace simbake {

namespace {

Vec3 row(const Points& x, int k) { return x.row(k).transpose(); }

// A triangle's frame [e1, n x e1, n] (columns); false for a degenerate triangle
bool triangle_frame(const Vec3& a, const Vec3& b, const Vec3& c, Mat3& frame) {
  const Vec3 edge = b - a, normal = edge.cross(c - a);
  if (!(edge.squaredNorm() > 0.0) || !(normal.squaredNorm() > 0.0)) return false;
  const Vec3 e1 = edge.normalized(), n = normal.normalized();
  frame.col(0) = e1;
  frame.col(1) = n.cross(e1);
  frame.col(2) = n;
  return true;
}

// A dynamic body takes the attachment's reaction a step late (as it takes the contacts'), so
// a body whose velocity the cloth could change more than its own inertia resists oscillates
// with a growing amplitude (an error e in its velocity comes back as -(m_cloth / M) e the next
// step). It must outweigh the cloth: its mass the cloth's at least, and its smallest moment of
// inertia the cloth's largest about the body's centre of mass (the cloth as a rigid body: an
// upper bound of what a flexible one drags along). Measured: a 0.06 kg sheet hanging from a
// box is carried by a box of 0.06 kg, and blows up under one of 0.045 kg.
void check_carrier(const Cloth& cloth, const ContactBody& body) {
  const Eigen::VectorXd& m = cloth.masses();
  Mat3 inertia = Mat3::Zero();
  for (int k = 0; k < cloth.vertex_count(); ++k) {
    const Vec3 r = row(cloth.positions(), k) - body.center;
    inertia += m[k] * (r.squaredNorm() * Mat3::Identity() - r * r.transpose());
  }
  const double mass = m.sum(), moment = Eigen::SelfAdjointEigenSolver<Mat3>(inertia).eigenvalues().maxCoeff();
  const double body_mass = 1.0 / body.inverse_mass, body_moment = 1.0 / body.inverse_inertia.maxCoeff();
  if (body_mass < mass || body_moment < moment) {
    char text[320];
    std::snprintf(text, sizeof text,
                  "a dynamic body carrying a cloth must outweigh it: the body has %.4g kg and a smallest moment of "
                  "inertia of %.4g kg m^2, the cloth %.4g kg and %.4g kg m^2 about the body's centre; make the body "
                  "heavier, or kinematic",
                  body_mass, body_moment, mass, moment);
    throw std::invalid_argument(text);
  }
}

}  // namespace

ClothMomentum cloth_momentum(const Cloth& cloth, const Vec3& center) {
  ClothMomentum p;
  const Points& x = cloth.positions();
  const Points& v = cloth.velocities();
  const Eigen::VectorXd& m = cloth.masses();
  for (int k = 0; k < cloth.vertex_count(); ++k) {
    const Vec3 momentum = m[k] * row(v, k);
    p.linear += momentum;
    p.angular += (row(x, k) - center).cross(momentum);
  }
  return p;
}

ClothAttachment::ClothAttachment(const Cloth& cloth, const std::vector<int>& vertices, int body,
                                 const ContactBodies& bodies)
    : body_(body), vertex_(vertices) {
  if (!(body >= 0 && body < bodies.count())) {
    throw std::invalid_argument("attachment: body " + std::to_string(body) + " does not exist");
  }
  if (vertices.empty()) throw std::invalid_argument("attachment: no vertex to attach");
  const ContactBody& b = bodies.body(body);
  if (!b.kinematic) check_carrier(cloth, b);
  const Points& x = cloth.positions();
  const int n = static_cast<int>(vertices.size());
  triangle_.assign(n, -1);
  weights_.assign(n, Vec3::Zero());
  offset_.assign(n, Vec3::Zero());
  for (int a = 0; a < n; ++a) {
    const int k = vertices[a];
    if (!(k >= 0 && k < cloth.vertex_count() && cloth.model().attached[k])) {
      throw std::invalid_argument("attachment: vertex " + std::to_string(k) + " is not one of the cloth's attached vertices");
    }
    const Vec3 p = row(x, k);
    if (!b.surface) {
      offset_[a] = b.pose.apply_inverse(p);
      continue;
    }
    // the nearest point of the deforming surface's mesh (its first triangle of the nearest, by index)
    const DeformingSurface& surface = *b.surface;
    const Triangles& tris = b.mesh->triangles;
    double nearest = std::numeric_limits<double>::infinity();
    for (int t = 0; t < tris.rows(); ++t) {
      const Vec3 va = surface.vertex(tris(t, 0), b.surface_end), vb = surface.vertex(tris(t, 1), b.surface_end),
                 vc = surface.vertex(tris(t, 2), b.surface_end);
      Mat3 f;
      if (!triangle_frame(va, vb, vc, f)) continue;
      const Vec3 w = closest_on_triangle(p, va, vb, vc);
      const Vec3 s = w[0] * va + w[1] * vb + w[2] * vc;
      const double d = (p - s).squaredNorm();
      if (d < nearest) {
        nearest = d;
        triangle_[a] = t;
        weights_[a] = w;
        offset_[a] = f.transpose() * (p - s);
      }
    }
    if (triangle_[a] < 0) throw std::invalid_argument("attachment: the deforming surface has no triangle of any area");
  }
  target_.resize(n, 3);
}

void ClothAttachment::prescribe(Cloth& cloth, const ContactBodies& bodies, double dt) {
  const ContactBody& b = bodies.body(body_);
  for (size_t a = 0; a < vertex_.size(); ++a) {
    Vec3 target;
    if (triangle_[a] < 0) {
      target = b.pose.apply(offset_[a]);
    } else {
      const Triangles& tris = b.mesh->triangles;
      const int t = triangle_[a];
      const Vec3 va = b.surface->vertex(tris(t, 0), b.surface_end), vb = b.surface->vertex(tris(t, 1), b.surface_end),
                 vc = b.surface->vertex(tris(t, 2), b.surface_end);
      // (a triangle crushed to no area has no frame: the vertex goes to its bound surface point)
      Mat3 frame;
      if (!triangle_frame(va, vb, vc, frame)) frame.setZero();
      target = weights_[a][0] * va + weights_[a][1] * vb + weights_[a][2] * vc + frame * offset_[a];
    }
    target_.row(a) = target.transpose();
    cloth.velocities().row(vertex_[a]) = ((target - row(cloth.positions(), vertex_[a])) / dt).transpose();
  }
  if (b.surface) {
    b.surface->affine_motion(b.surface_start, motion_.A, motion_.c);
  } else {
    const Mat3 turn = b.pose.rotation * b.start_pose.rotation.transpose();
    motion_.A = (turn - Mat3::Identity()) / dt;
    motion_.c = (b.pose.translation - turn * b.start_pose.translation) / dt;
  }
}

void AttachmentReaction::begin(const Cloth& cloth, const Vec3& center, const Vec3& gravity, double dt) {
  on_ = true;
  center_ = center;
  given_ = ClothMomentum();
  const ClothModel& m = cloth.model();
  for (int k = 0; k < cloth.vertex_count(); ++k) {
    if (!m.pinned[k] || m.attached[k]) not_given(cloth, k, dt * m.mass[k] * gravity);
  }
}

void AttachmentReaction::add_since(const Cloth& cloth, const ClothMomentum& before) {
  const ClothMomentum after = cloth_momentum(cloth, center_);
  given_.linear += after.linear - before.linear;
  given_.angular += after.angular - before.angular;
}

void AttachmentReaction::not_given(const Cloth& cloth, int k, const Vec3& J) {
  given_.linear -= J;
  given_.angular -= (row(cloth.positions(), k) - center_).cross(J);
}

void ClothAttachment::place(Cloth& cloth) const {
  for (size_t a = 0; a < vertex_.size(); ++a) cloth.positions().row(vertex_[a]) = target_.row(a);
}

}  // namespace simbake
