// Collision impulses between two bodies at one point, exactly as in the seed notes
// ("Finding the impulse" through "Static friction test").
//
// Body 1 receives J, body 2 receives -J. With r = x - X the lever arm from a body's centre of
// mass, the point velocity changes by K J where
//     K_body = (1/M) Id + r*^T I^-1 r*      (r* the cross-product matrix of r)
// and K = K_1 + K_2 for the pair (the ground and kinematic bodies contribute K = 0).
// v is the relative velocity v_1 - v_2 at the point and n the unit normal pointing from body
// 2 towards body 1, so v.n < 0 means the bodies approach.
#pragma once

#include "math/types.h"

namespace simbake {

// K of one body for a point at lever arm r; inverse_inertia is the world-space I^-1 (1/(kg m^2))
Mat3 impulse_matrix(double inverse_mass, const Mat3& inverse_inertia, const Vec3& r);

// Frictionless: J = j n with j = -(1 + e) n.v / (n.K n)
Vec3 frictionless_impulse(const Mat3& K, const Vec3& n, const Vec3& v, double restitution);

// Static friction: the J that leaves v_after = -e (v.n) n, i.e. J = -K^-1 (v + e (v.n) n)
Vec3 static_impulse(const Mat3& K, const Vec3& n, const Vec3& v, double restitution);

// Friction-cone test: |J - (J.n) n| <= mu |J.n| (with a relative slack of 1e-12)
bool inside_friction_cone(const Vec3& J, const Vec3& n, double friction);

// Sliding friction: J = j (n - mu T), T = v_T / |v_T|, j = -(1 + e) n.v / (n.K (n - mu T)).
// With v_T = 0 there is no friction direction and this is the frictionless impulse.
Vec3 sliding_impulse(const Mat3& K, const Vec3& n, const Vec3& v, double restitution, double friction);

// Coulomb friction as the notes prescribe: the static impulse if it lies in the friction
// cone, else the sliding impulse on the cone. friction == 0 skips the friction math.
Vec3 coulomb_impulse(const Mat3& K, const Vec3& n, const Vec3& v, double restitution, double friction);

}  // namespace simbake
