// A cloth against the bodies and the ground: its contacts, the contacts its implicit solve
// holds, and the pinches it holds open between two surfaces. The method is at the top of
// cloth_body_contact.cpp.
//
// The contact code does not see the world. It sees the bodies through ContactBodies: one
// ContactBody per body, fixed over a cloth's step (shape, pose, bounding sphere, friction,
// flags, the mesh for features), and the bodies' live velocity state, which every contact
// reads and changes at once (an impulse on a body is there for the next contact to see):
// the surface velocity at a point, an impulse at a point, waking a body, and, for the
// pinches, the inverse inertia and a pseudo-velocity that moves a body's position only. The
// world implements it over its own arrays (world/cloth_stages.cpp) and calls the stages of a
// ClothBodyContact, one per cloth, which owns the cloth's contact state and scratch.
#pragma once

#include "cloth/cloth.h"
#include "contact/body_features.h"
#include "geometry/mesh.h"
#include "levelset/signed_distance.h"
#include "math/types.h"
#include "rigid/rigid_body.h"

#include <array>
#include <optional>
#include <vector>

namespace simbake {

// One body as a cloth's contacts see it: fixed over the contact stages of a cloth's step
// (the pinches move bodies only at the very end of them)
struct ContactBody {
  const SignedDistance* shape = nullptr;  // level set, mesh coordinates; null: no contact
  const TriangleMesh* mesh = nullptr;     // the closed mesh of a level-set body (its sharp
                                          // edges are features), or null or empty
  Pose pose;                              // mesh coordinates to world
  Pose start_pose;                        // the same at the start of the cloth's step (for a
                                          // cloth stepped over several body substeps, before the first)
  Vec3 center = Vec3::Zero();             // centre of mass, world (m)
  double bounding_radius = 0.0;           // about the centre of mass (m)
  double friction = 0.5;                  // Coulomb coefficient
  double inverse_mass = 0.0;              // (1/kg); 0 for kinematic bodies
  bool kinematic = false;
  bool still = false;                     // static, or kinematic and not moving this step
  // (cloth vertices) or null: the vertices this body, kinematic and moving, passes through
  // this step, no contact pushing them out (a keyed obstacle the cloth has let in:
  // contact/cloth_obstacles.h); it passes through those inside it at the step's start that a
  // still surface holds, too
  const std::vector<char>* let_in = nullptr;
};

// The ground plane y = height, as the contacts see it
struct ContactGround {
  double height = 0.0;    // (m)
  double friction = 0.5;  // Coulomb coefficient
};

// The bodies the cloth touches, by index (0 .. count()); the ground is not one of them
class ContactBodies {
 public:
  virtual ~ContactBodies() = default;
  virtual int count() const = 0;
  virtual const ContactBody& body(int b) const = 0;
  virtual const ContactGround* ground() const = 0;  // null: no ground
  // live: a sleeping body takes no impulse; waking b wakes its island
  virtual bool asleep(int b) const = 0;
  virtual void wake(int b) = 0;
  // the velocity of body b's surface at world point p, now (m/s)
  virtual Vec3 velocity_at(int b, const Vec3& p) const = 0;
  // impulse J (N s) at world point p on dynamic body b: v += J / m, L += (p - center) x J
  virtual void apply_impulse(int b, const Vec3& p, const Vec3& J) = 0;
  // world I^-1 of dynamic body b now (1/(kg m^2))
  virtual Mat3 inverse_inertia(int b) const = 0;
  // moves dynamic body b's position only, by a pseudo-velocity (v m/s, omega rad/s) over dt:
  // center += dt v, orientation turned by omega over dt; its velocities stay
  virtual void displace(int b, const Vec3& v, const Vec3& omega, double dt) = 0;
};

// One cloth's contacts with the bodies and the ground, and what they keep from one step to
// the next. The stages, in the order a cloth step calls them:
//   contact_constraints        the contacts the implicit solve holds (before it), or
//                              forget_touches when the solve holds none
//   apply_constraint_impulses  their friction, and which are let go (after it)
//   collide                    the candidates x + dt v pushed out to the thickness (many times)
//   hold_pinched_bodies        bodies pinching the cloth held apart (last)
class ClothBodyContact {
 public:
  ClothBodyContact(const Cloth& cloth, double friction, double thickness);

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
  double surface_friction(const ContactBodies& bodies, int b) const;
  // body b's features against the cloth (spaced for its edges), made at the first call
  const BodyFeatures& body_features(const ContactBodies& bodies, int b);
  // a body's corners and edges against the cloth's triangles, and its edges against the
  // cloth's edges: calls contact(ids, w, count, xc, normal, phi) per contact (count 3: a
  // triangle's vertices, 2: an edge's)
  template <class Contact>
  bool collide_features(const Cloth& cloth, const ContactBodies& bodies, int b, double dt, const Contact& contact);

  double friction_;                             // Coulomb coefficient against bodies and ground
  double thickness_;                            // distance kept from surfaces (and, by self-collision, itself) (m)
  Eigen::VectorXd inverse_mass_;                // (nvert) 1/kg, 0 when pinned
  std::vector<std::array<int, 2>> edges_;       // (nedge) vertex pairs, i < j
  double mean_edge_;                            // mean rest edge length (m)
  Touches touches_;
  TriangleGrid grid_;                           // scratch: the triangles at the candidate positions
  std::vector<std::array<int, 3>> triangle_edges_;  // (ntri) each triangle's edges (indices into edges_)
  std::vector<int> triangle_seen_, edge_seen_;  // scratch: the body edge that last looked at each (collide_features)
  int edge_mark_ = -1;                          // the last body edge's mark
  std::vector<std::optional<BodyFeatures>> body_features_;  // (nbody) made at first use
};

}  // namespace simbake
