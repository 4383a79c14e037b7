// The bodies as a cloth's contacts see them, and what the contacts do to them.
//
// The contact code does not see the world, nor change its state. Its caller describes each
// body once per cloth step (ContactBody: shape, pose, mass properties, flags) with its
// velocities and sleep then; the contacts read and change those velocities in this buffer as
// they go (an impulse on a body is there for the next contact to see), and record what they
// did, in order: the impulses, the islands they woke, the displacements of the pinches. The
// owner of the bodies applies that record afterwards (world/cloth_coupling.h), the same
// arithmetic in the same order, so its bodies end as this buffer's do, bit for bit.
#pragma once

#include "levelset/deforming_surface.h"
#include "geometry/mesh.h"
#include "levelset/signed_distance.h"
#include "math/types.h"
#include "rigid/rigid_body.h"

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
  Quat orientation = Quat::Identity();    // principal frame -> world
  double bounding_radius = 0.0;           // about the centre of mass (m)
  double friction = 0.5;                  // Coulomb coefficient
  double inverse_mass = 0.0;              // (1/kg); 0 for kinematic bodies
  Vec3 inverse_inertia = Vec3::Zero();    // principal inverse moments (1/(kg m^2)); 0 for kinematic bodies
  bool isotropic = false;                 // equal principal moments (RigidBodyDef::isotropic)
  Vec3 spin = Vec3::Zero();               // a kinematic body's prescribed angular velocity (rad/s, world)
  bool kinematic = false;
  bool still = false;                     // static, or kinematic and not moving this step
  int island = 0;                         // its sleeping island: waking it wakes every sleeper of the island
  // (cloth vertices) or null: the vertices this body, kinematic and moving, passes through
  // this step, no contact pushing them out (a keyed obstacle the cloth has let in:
  // contact/cloth_obstacles.h); it passes through those inside it at the step's start that a
  // still surface holds, too
  const std::vector<char>* let_in = nullptr;
  // a deforming collider (kinematic, its mesh pose the identity): its surface over the frame,
  // and where in the frame the cloth's step starts and ends (DeformingSurface::blend); `shape`
  // is the surface's level set at `surface_end`, and its mesh the surface's topology
  const DeformingSurface* surface = nullptr;
  double surface_start = 0.0;
  double surface_end = 1.0;
};

// The ground plane y = height, as the contacts see it
struct ContactGround {
  double height = 0.0;    // (m)
  double friction = 0.5;  // Coulomb coefficient
};

// An impulse J (N s) the contacts gave body b at world point p, and an angular impulse
// (N m s, about its centre of mass) besides
struct BodyImpulse {
  int body;
  Vec3 point;
  Vec3 impulse;
  Vec3 angular = Vec3::Zero();
};

// A move of body b's position only, by a pseudo-velocity (v m/s, omega rad/s) over dt (s):
// center += dt v, orientation turned by omega over dt; its velocities stay
struct BodyDisplacement {
  int body;
  Vec3 velocity;
  Vec3 omega;
  double dt;
};

// The bodies the cloth touches, by index (0 .. count()); the ground is not one of them
class ContactBodies {
 public:
  // No bodies and no ground, nothing done (keeps the buffers' memory)
  void clear();
  // Adds a body with its velocity (m/s), angular momentum (kg m^2/s, world) and sleep now
  void add(const ContactBody& body, const Vec3& velocity, const Vec3& angular_momentum, bool asleep);
  void set_ground(const ContactGround& ground) { ground_ = ground; }
  // the cloth vertices body b passes through this step (ContactBody::let_in), or null
  void set_let_in(int b, const std::vector<char>* vertices) { bodies_[b].let_in = vertices; }

  int count() const { return static_cast<int>(bodies_.size()); }
  const ContactBody& body(int b) const { return bodies_[b]; }
  const ContactGround* ground() const { return ground_ ? &*ground_ : nullptr; }  // null: no ground
  // a sleeping body takes no impulse; waking b wakes its island
  bool asleep(int b) const { return asleep_[b] != 0; }
  void wake(int b);
  // the velocity of body b's surface at world point p, now (m/s)
  Vec3 velocity_at(int b, const Vec3& p) const {
    const ContactBody& body = bodies_[b];
    if (body.surface) return body.surface->velocity_at(p);
    const Vec3 omega = body.kinematic ? body.spin
                                      : angular_velocity(body.inverse_inertia, body.isotropic, body.orientation, l_[b]);
    return v_[b] + omega.cross(p - body.center);
  }
  // impulse J (N s) at world point p on dynamic body b: v += J / m, L += (p - center) x J
  void apply_impulse(int b, const Vec3& p, const Vec3& J) {
    v_[b] += bodies_[b].inverse_mass * J;
    l_[b] += (p - bodies_[b].center).cross(J);
    impulses_.push_back({b, p, J});
  }
  // impulse J (N s) and angular impulse H (N m s, about its centre of mass) on dynamic body b:
  // v += J / m, L += H (a cloth's attachment: contact/cloth_attachment.h)
  void apply_wrench(int b, const Vec3& J, const Vec3& H) {
    v_[b] += bodies_[b].inverse_mass * J;
    l_[b] += H;
    impulses_.push_back({b, bodies_[b].center, J, H});
  }
  // world I^-1 of dynamic body b now (1/(kg m^2))
  Mat3 inverse_inertia(int b) const {
    const ContactBody& body = bodies_[b];
    return world_inverse_inertia(body.inverse_inertia, body.isotropic, body.orientation);
  }
  // moves dynamic body b's position only (see BodyDisplacement), once the contacts are done
  void displace(int b, const Vec3& v, const Vec3& omega, double dt) { displacements_.push_back({b, v, omega, dt}); }

  // body b's velocity (m/s) and angular momentum (kg m^2/s) with the impulses so far
  const Vec3& velocity(int b) const { return v_[b]; }
  const Vec3& angular_momentum(int b) const { return l_[b]; }
  // what the contacts did, in order, for the owner of the bodies to apply
  const std::vector<BodyImpulse>& impulses() const { return impulses_; }
  const std::vector<int>& woken() const { return woken_; }  // bodies whose island was woken
  const std::vector<BodyDisplacement>& displacements() const { return displacements_; }

 private:
  std::vector<ContactBody> bodies_;
  std::optional<ContactGround> ground_;
  std::vector<Vec3> v_, l_;                     // (nbody) live velocities (m/s, kg m^2/s)
  std::vector<char> asleep_;                    // (nbody) live sleep
  std::vector<BodyImpulse> impulses_;
  std::vector<int> woken_;
  std::vector<BodyDisplacement> displacements_;
};

}  // namespace simbake
