// A cloth against the bodies and the ground: its contacts, the contacts its implicit solve
// holds, and the pinches it holds open between two surfaces. The method is at the top of
// cloth_body_contact.cpp.
//
// The contact code does not see the world. It sees the bodies through ContactBodies
// (contact_bodies.h): each body as it is when the cloth's step begins, with the velocities
// the contacts read and change as they go, and the record of what they did to the bodies,
// which the world applies (world/cloth_coupling.h). The cloth's step (cloth/cloth_step.h)
// calls the stages of a ClothBodyContact, one per cloth, which owns the cloth's contact state
// and scratch.
#pragma once

#include "cloth/cloth.h"
#include "contact/body_features.h"
#include "contact/cloth_nearby.h"
#include "contact/contact_bodies.h"
#include "geometry/mesh.h"
#include "levelset/signed_distance.h"
#include "math/types.h"
#include "rigid/rigid_body.h"

#include <array>
#include <optional>
#include <vector>

namespace simbake {

// One cloth's contacts with the bodies and the ground, and what they keep from one step to
// the next. The stages, in the order a cloth step calls them:
//   contact_constraints        the contacts the implicit solve holds (before it), or
//                              forget_touches when the solve holds none
//   apply_constraint_impulses  their friction, and which are let go (after it)
//   collide                    the candidates x + dt v pushed out to the thickness (many times)
//   hold_pinched_bodies        bodies pinching the cloth held apart (last)
class ClothBodyContact {
 public:
  // against the bodies with the cloth's friction, keeping its thickness from them
  explicit ClothBodyContact(const Cloth& cloth);

  double friction() const { return friction_; }
  double thickness() const { return thickness_; }
  double mean_edge() const { return mean_edge_; }  // the cloth's mean rest edge length (m)
  const Eigen::VectorXd& inverse_mass() const { return inverse_mass_; }
  const std::vector<std::array<int, 2>>& edges() const { return edges_; }
  // (nvert) for each vertex, the sum of the normals of the still surfaces (the ground, static
  // bodies, kinematic ones not moving) whose contacts pushed it or held it this step, by
  // weight; zero where none did (self-collision's SelfCollisionSettings::support)
  const std::vector<Vec3>& support() const { return touches_.normal; }

  void contact_constraints(const Cloth& cloth, const ContactBodies& bodies, std::vector<ClothContactConstraint>& out);
  // this step's contacts recorded afresh (contact_constraints does it after reading the last
  // step's; a step without it calls this instead)
  void forget_touches();
  void apply_constraint_impulses(Cloth& cloth, const ContactBodies& bodies,
                                 const std::vector<ClothContactConstraint>& constraints);
  void collide(Cloth& cloth, ContactBodies& bodies, double dt);
  void hold_pinched_bodies(const Cloth& cloth, ContactBodies& bodies, double dt);

 private:
  // the cloth's contacts with bodies, from one step to the next (contact_constraints)
  struct Touches {
    std::vector<Vec3> normal;  // (nvert) the sum of the normals of the contacts that pushed it this step, by weight
    std::vector<int> body;     // (nvert) the body of the last of them (-1: the ground)
    std::vector<char> released;  // (nvert) its constraint pulled last step: not held this step
    std::vector<char> stuck;     // (nvert) friction stopped its slip: held in every direction
    std::vector<int> constrained_body;  // (constraints) scratch: each constraint's body
  };
  // a cloth vertex pinched between two surfaces (hold_pinched_bodies)
  struct Pinch {
    Vec3 point;
    int a, b;      // the two surfaces' bodies (-1: the ground)
    Vec3 normal;   // from a towards b
    double gap;    // phi_a + phi_b (m)
    double width;  // of the spacer: (layers + 1) h, at least kPinchGap h (m)
  };
  std::vector<Pinch> find_pinches(const Cloth& cloth, const ContactBodies& bodies, double dt, const std::vector<int>& near,
                                  const Box3& reach);
  void separate_pinches(ContactBodies& bodies, double dt, const std::vector<int>& near, const std::vector<Pinch>& pinches);
  double surface_friction(const ContactBodies& bodies, int b) const;
  // one contact of a point of the cloth (collide), and the cloth against one body
  void contact_point(const Points& x, Points& v, ContactBodies& bodies, double dt, const int* ids, const double* w,
                     int count, int body, const Vec3& xc, const Vec3& normal, double phi, double mu);
  void collide_with_body(Cloth& cloth, ContactBodies& bodies, int b, const Box3& reach, double dt);
  // body b's features against the cloth (spaced for its edges), made at the first call
  const BodyFeatures& body_features(const ContactBodies& bodies, int b);
  // a body's corners and edges against the cloth's triangles, and its edges against the
  // cloth's edges: calls contact(ids, w, count, xc, normal, phi) per contact (count 3: a
  // triangle's vertices, 2: an edge's)
  template <class Contact>
  bool collide_features(const Cloth& cloth, const ContactBodies& bodies, int b, double dt, const Contact& contact);
  // the body's sharp edges against the cloth's edges (collide_features' second part: the grid
  // is the one it built for the body)
  template <class Contact>
  bool collide_feature_edges(const Cloth& cloth, const ContactBodies& bodies, int b, double dt,
                             const BodyFeatures& features, const Contact& contact);

  double friction_;                             // Coulomb coefficient against bodies and ground
  double thickness_;                            // distance kept from surfaces (and, by self-collision, itself) (m)
  Eigen::VectorXd inverse_mass_;                // (nvert) 1/kg, 0 when pinned
  std::vector<std::array<int, 2>> edges_;       // (nedge) vertex pairs, i < j
  double mean_edge_;                            // mean rest edge length (m)
  Touches touches_;
  TriangleGrid grid_;                           // scratch: the triangles at the candidate positions
  // (nvert x 3) collide's candidates x + dt v, kept as its contacts change v, and which of
  // them are near each body (contact/cloth_nearby.h)
  Points candidates_;
  ClothNearby nearby_;
  // each triangle's plane at the candidates (triangle_plane), kept while none of its vertices
  // changes: a stamp counts the passes' starts and the candidates' changes
  struct TrianglePlane {
    Vec3 winding = Vec3::Zero();
    double twice_area = 0.0;
    long long at = -1;  // the stamp when it was taken
  };
  std::vector<TrianglePlane> planes_;      // (ntri)
  std::vector<long long> vertex_changed_;  // (nvert) the stamp when its candidate last changed
  long long stamp_ = 0, pass_stamp_ = 0;   // now, and at this pass's start
  std::vector<std::array<int, 3>> triangle_edges_;  // (ntri) each triangle's edges (indices into edges_)
  std::vector<int> triangle_seen_, edge_seen_;  // scratch: the body edge that last looked at each (collide_features)
  int edge_mark_ = -1;                          // the last body edge's mark
  std::vector<std::optional<BodyFeatures>> body_features_;  // (nbody) made at first use
};

}  // namespace simbake
