// A cloth's points attached to one body's surface (a cape sewn to the shoulders, a flag on a
// carried pole): bound when the attachment is made (the first frame) and carried with the
// surface exactly from then on; the method is at the top of cloth_attachment.cpp.
//
// The cloth's step (cloth/cloth_step.cpp) calls, in order: prescribe (the attached vertices'
// velocities over the step, before anything else), motion (the impact zones holding attached
// vertices move with it), place (the vertices put exactly where the surface carried them,
// after the positions), and, for a dynamic body, reaction (what the attachment gave the cloth,
// from momentum the step measured, given back to the body).
#pragma once

#include "cloth/cloth.h"
#include "cloth/self_collision.h"
#include "contact/contact_bodies.h"
#include "math/types.h"

#include <vector>

namespace simbake {

// The momentum of a cloth (kg m/s) and its angular momentum about a point (kg m^2/s)
struct ClothMomentum {
  Vec3 linear = Vec3::Zero();
  Vec3 angular = Vec3::Zero();
};

// Σ m v and Σ m (x - center) x v over the cloth's vertices now
ClothMomentum cloth_momentum(const Cloth& cloth, const Vec3& center);

// What a cloth's attachment gives it over one step, for a dynamic body to take back
// (cloth_attachment.cpp, "Reaction"): the change of the cloth's momentum, and of its angular
// momentum about the body's centre of mass, over the stages the attachment acts in, less what
// else acts in them. Off (measuring nothing) until begun
class AttachmentReaction {
 public:
  // A step begins: about `center` (m), the weight over dt (s) of what hangs from the
  // attachment (the cloth's free and attached vertices; a pinned one's is its pin's) not the
  // attachment's
  void begin(const Cloth& cloth, const Vec3& center, const Vec3& gravity, double dt);
  bool on() const { return on_; }
  // f() run, the cloth's change of momentum over it the attachment's
  template <class F>
  void measured(const Cloth& cloth, F&& f) {
    if (!on_) return f();
    const ClothMomentum before = cloth_momentum(cloth, center_);
    f();
    add_since(cloth, before);
  }
  // the cloth's change of momentum since `before`, the attachment's
  void add_since(const Cloth& cloth, const ClothMomentum& before);
  // an impulse J (N s) on vertex k in a measured stage that was not the attachment's
  void not_given(const Cloth& cloth, int k, const Vec3& J);
  const ClothMomentum& given() const { return given_; }  // so far this step
  const Vec3& center() const { return center_; }

 private:
  bool on_ = false;
  Vec3 center_ = Vec3::Zero();
  ClothMomentum given_;
};

class ClothAttachment {
 public:
  // The cloth vertices `vertices` (the cloth's ClothDesc::attached) bound where they are now
  // (`cloth`'s positions) to body `body` of `bodies`, as they describe it now
  ClothAttachment(const Cloth& cloth, const std::vector<int>& vertices, int body, const ContactBodies& bodies);

  int body() const { return body_; }
  const std::vector<int>& vertices() const { return vertex_; }  // (attached) cloth vertex
  // (attached) the surface triangle each is bound to (-1: bound in a rigid body's frame)
  const std::vector<int>& triangles() const { return triangle_; }

  // Each attached vertex's carried position at the end of the cloth's step (the body at its
  // ContactBody::pose, or a deforming surface at surface_end), and the velocity (m/s) that
  // takes it there over dt (s) from where it is, set on the cloth
  void prescribe(Cloth& cloth, const ContactBodies& bodies, double dt);
  // The surface's motion over the step as a velocity field (self-collision's impact zones
  // that hold attached vertices move with it): a rigid body's exactly, a deforming surface's
  // nearest affine field (DeformingSurface::affine_motion)
  const ObstacleMotion& motion() const { return motion_; }
  // The attached vertices put exactly on their carried positions (after the step's positions)
  void place(Cloth& cloth) const;
  // Whether the body takes the attachment's reaction: dynamic
  bool reacting(const ContactBodies& bodies) const { return !bodies.body(body_).kinematic; }

 private:
  int body_;
  std::vector<int> vertex_;    // (attached) cloth vertex
  std::vector<int> triangle_;  // (attached) deforming: the bound triangle; -1: rigid
  std::vector<Vec3> weights_;  // (attached) deforming: barycentric weights of the bound point
  std::vector<Vec3> offset_;   // (attached) deforming: the offset in the triangle's frame;
                               // rigid: the vertex in the body's mesh frame (m)
  Points target_;              // (attached x 3) carried positions at the step's end (m)
  ObstacleMotion motion_;
};

}  // namespace simbake
