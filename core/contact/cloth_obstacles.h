// The bodies a cloth's self-collision treats as obstacles (cloth/self_collision.h): the
// kinematic bodies with sharp features, a box or a mesh (a table, a pole, a keyed mover).
//
// The cloth's contacts (cloth_body_contact.h) hold its vertices, edge points and the
// bodies' sharp features apart at the end of the step, in turn with strain limiting and
// self-collision; self-collision has the last word, and its impulses could carry a cloth
// edge back across a body's edge that the contacts had cleared (a keyed box pushed into a
// sheet on the ground puts its edges through the sheet so). As obstacles of infinite mass inside self-collision, the bodies' triangles take
// part in its continuous test and impact zones, so that the step's last word keeps the
// cloth and the body's corners and edges from passing through each other.
//
// Only kinematic bodies: a dynamic body takes the cloth's push back (the contacts give it
// the opposite momentum, the pinches move it), which an obstacle of infinite mass cannot;
// curved shapes (spheres, capsules) have no edges to poke through a triangle, and the
// contacts keep the cloth's points off them.
//
// Each step the obstacles' vertices run on lines from the body's pose at the start of the
// cloth's step (ContactBody::start_pose) to its pose now, the same x + s dt v as the cloth's;
// a deforming surface's vertices each on its own line (contact/deforming_surface.h).
// The self-collision sees the cloth's vertices and then the obstacles' in one set of
// arrays, made here: load() before each self-collision call, store() after it.
#pragma once

#include "contact/cloth_body_contact.h"
#include "geometry/mesh.h"
#include "math/types.h"
#include "cloth/self_collision.h"

#include <vector>

namespace simbake {

class ClothObstacles {
 public:
  // Picks the obstacles among the bodies; true when they differ from the last call's (the
  // self-collision must be made again with meshes())
  bool select(const ContactBodies& bodies);
  bool empty() const { return body_.empty(); }
  const std::vector<int>& bodies() const { return body_; }  // (obstacles) body index
  // (obstacles) each obstacle's mesh in its own coordinates (a box's 8 corners)
  const std::vector<TriangleMesh>& meshes() const { return mesh_; }

  // The step's arrays: the cloth's positions and inverse masses, then the obstacles' vertices
  // at the start pose and their velocities to the pose now, inverse mass 0; and each
  // obstacle's motion (the velocity field of its lines). `give` (m): when the cloth is
  // stretched past what its strain limit can hold, the reach of its giving (see yielding); 0
  // when it is not
  void begin_step(const Cloth& cloth, const ContactBodies& bodies, const Eigen::VectorXd& inverse_mass, double dt,
                  double give = 0.0);
  const Points& positions() const { return x_; }
  Points& velocities() { return v_; }
  const Eigen::VectorXd& inverse_mass() const { return inverse_mass_; }
  const std::vector<ObstacleMotion>& motions() const { return motion_; }
  // (n) 1 for the cloth's free vertices that no obstacle keeps out in this step
  // (SelfCollisionSettings::yielding): those inside one at the step's start, and, when the
  // cloth gives, those within `give` of one. A keyed box pushing a cloth held
  // by its pins carries it along (the obstacles' continuous test and impact zones keep the
  // cloth out of the box) until the cloth gives: stretched past kGiveStrain times its limit,
  // it lets the box through, and the box no longer holds the vertices it has let in
  const std::vector<char>& yielding() const { return yielding_; }
  bool any_yielding() const { return any_yielding_; }
  const std::vector<Vec3>& support() const { return support_; }
  // the cloth's velocities and supports into the arrays; the cloth's velocities back out
  void load(const Points& cloth_velocities, const std::vector<Vec3>& cloth_support);
  void store(Points& cloth_velocities) const;
  // a per-vertex array of the cloth's rows only, or grown by zero rows for the obstacles
  std::vector<char> cloth_part(const std::vector<char>& all) const;
  Points padded(const Points& cloth_rows) const;

 private:
  Eigen::Index deforming_rows(const DeformingSurface& surface, double s0, double s1, double dt, Eigen::Index row,
                              ObstacleMotion& motion);

  std::vector<int> body_;             // (obstacles) body index
  std::vector<TriangleMesh> mesh_;    // (obstacles)
  int cloth_vertices_ = 0;
  Points x_, v_;
  Eigen::VectorXd inverse_mass_;
  std::vector<Vec3> support_;
  std::vector<ObstacleMotion> motion_;
  std::vector<char> yielding_;
  bool any_yielding_ = false;
};

}  // namespace simbake
