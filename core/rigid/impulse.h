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
// With v_T = 0 there is no friction direction and this is the frictionless impulse; so it is
// when n.K(n - mu T) <= 0 (large mu on a long lever arm), where the sliding impulse would
// pull instead of push.
Vec3 sliding_impulse(const Mat3& K, const Vec3& n, const Vec3& v, double restitution, double friction);

// Kinetic energy the pair gains from impulse J at a point with relative velocity v (J):
// dE = J.v + J.K J / 2. Over all J it is smallest, -v.K^-1 v / 2, at J = -K^-1 v, so dE <= 0
// exactly when |v_after|_K^-1 <= |v|_K^-1.
double impulse_energy_change(const Mat3& K, const Vec3& v, const Vec3& J);

// Coulomb friction as the notes prescribe: the static impulse if it lies in the friction
// cone, else the sliding impulse on the cone. friction == 0 skips the friction math. No
// impact may gain energy, but both can: the static impulse with e > 0 changes the energy by
// (e^2 (n.v)^2 n.K^-1 n - v.K^-1 v) / 2, positive for some v when K is anisotropic (a hit
// off the centre line), and the sliding impulse when the slip reverses (Kane's paradox).
// Such an impulse is replaced by the frictionless one, which never gains (for e <= 1).
Vec3 coulomb_impulse(const Mat3& K, const Vec3& n, const Vec3& v, double restitution, double friction);

// One projected Gauss-Seidel update of a contact point's total impulse (the contact stage,
// where many points share a load and are solved in turn until nothing changes).
//   total: the impulse the point has given body 1 so far this stage (N s)
//   v:     the point's relative velocity now, with that impulse in it
// Normal part: j_n <- max(0, j_n - v.n / (n.K n)), the inelastic impulse along n that may
// push but never pull. Friction part, with the velocity after the normal update: along the
// slip direction T = v_T / |v_T|, j_T <- j_T - |v_T| / (T.K T) T, then projected radially
// onto the cone |j_T| <= mu j_n. The fixed points are Coulomb's law: either no slip with the
// impulse inside the cone (static friction), or slip with the friction on the cone exactly
// against it (sliding, maximal dissipation). The notes' one-shot formulas (static impulse,
// cone test, sliding impulse with T from the velocity before the impulse) solve the same law
// for a single point; iterated over the points of a face they fan the friction out of line
// with the rotational coupling of off-centre points (anisotropic K), and a box on a slope
// creeps where it must stick. target_speed >= 0 asks for that separating normal speed
// instead of 0 (penetration recovery). Returns the new total.
Vec3 contact_impulse_update(const Mat3& K, const Vec3& n, const Vec3& v, const Vec3& total, double friction,
                            double target_speed = 0.0);

}  // namespace simbake
