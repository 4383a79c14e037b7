#include "rigid/impulse.h"

#include <cmath>

namespace simbake {

Mat3 impulse_matrix(double inverse_mass, const Mat3& inverse_inertia, const Vec3& r) {
  const Mat3 rx = skew(r);
  return inverse_mass * Mat3::Identity() + rx.transpose() * inverse_inertia * rx;
}

Vec3 frictionless_impulse(const Mat3& K, const Vec3& n, const Vec3& v, double restitution) {
  const double j = -(1.0 + restitution) * n.dot(v) / n.dot(K * n);
  return j * n;
}

Vec3 static_impulse(const Mat3& K, const Vec3& n, const Vec3& v, double restitution) {
  // K is symmetric positive definite whenever one of the bodies has finite mass
  return -K.ldlt().solve(v + restitution * v.dot(n) * n);
}

bool inside_friction_cone(const Vec3& J, const Vec3& n, double friction) {
  const double jn = J.dot(n);
  const Vec3 tangential = J - jn * n;
  return jn >= 0.0 && tangential.norm() <= friction * std::abs(jn) * (1.0 + 1e-12);
}

Vec3 sliding_impulse(const Mat3& K, const Vec3& n, const Vec3& v, double restitution, double friction) {
  const Vec3 vt = v - v.dot(n) * n;
  const double vt_norm = vt.norm();
  if (vt_norm <= 1e-14 * (1.0 + v.norm())) return frictionless_impulse(K, n, v, restitution);
  const Vec3 direction = n - friction * (vt / vt_norm);
  const double denominator = n.dot(K * direction);
  // n.K(n - mu T) can only vanish or turn negative for large mu on a long lever arm; then the
  // sliding impulse would pull instead of push, and the frictionless one is the safe answer
  if (!(denominator > 1e-12 * n.dot(K * n))) return frictionless_impulse(K, n, v, restitution);
  const double j = -(1.0 + restitution) * n.dot(v) / denominator;
  return j * direction;
}

Vec3 coulomb_impulse(const Mat3& K, const Vec3& n, const Vec3& v, double restitution, double friction) {
  if (friction <= 0.0) return frictionless_impulse(K, n, v, restitution);
  const Vec3 J = static_impulse(K, n, v, restitution);
  if (inside_friction_cone(J, n, friction)) return J;
  return sliding_impulse(K, n, v, restitution, friction);
}

}  // namespace simbake
