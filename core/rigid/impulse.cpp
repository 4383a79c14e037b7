#include "rigid/impulse.h"

#include <algorithm>
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
  if (!(denominator > 1e-12 * n.dot(K * n))) return frictionless_impulse(K, n, v, restitution);
  return (-(1.0 + restitution) * n.dot(v) / denominator) * direction;
}

double impulse_energy_change(const Mat3& K, const Vec3& v, const Vec3& J) {
  // dE = J.(v + v_after) / 2 with v_after = v + K J: the work of J on the average velocity
  return J.dot(v + 0.5 * (K * J));
}

Vec3 coulomb_impulse(const Mat3& K, const Vec3& n, const Vec3& v, double restitution, double friction) {
  const Vec3 frictionless = frictionless_impulse(K, n, v, restitution);
  if (friction <= 0.0) return frictionless;
  Vec3 J = static_impulse(K, n, v, restitution);
  if (!inside_friction_cone(J, n, friction)) J = sliding_impulse(K, n, v, restitution, friction);
  // an impulse that would gain energy (see the header) gives way to the frictionless one,
  // whose change is -(1 - e^2) (n.v)^2 / (2 n.K n) <= 0
  return impulse_energy_change(K, v, J) > 0.0 ? frictionless : J;
}

Vec3 contact_impulse_update(const Mat3& K, const Vec3& n, const Vec3& v, const Vec3& total, double friction,
                            double target_speed) {
  // normal: push only
  const double jn_old = total.dot(n);
  const double jn = std::max(0.0, jn_old + (target_speed - v.dot(n)) / n.dot(K * n));
  Vec3 jt = total - jn_old * n;
  if (friction <= 0.0 || jn == 0.0) return jn * n;
  // friction along the slip, with the velocity the normal update leaves
  // (the slip s = |s| T is stopped by -(|s| / T.K T) T = -(s.s / s.K s) s: no square root)
  const Vec3 v_after = v + K * ((jn - jn_old) * n);
  const Vec3 slip = v_after - v_after.dot(n) * n;
  const double slip_squared = slip.squaredNorm(), slip_k = slip.dot(K * slip);
  if (slip_squared > 0.0 && slip_k > 0.0) jt -= (slip_squared / slip_k) * slip;
  // onto the cone; when it binds, the magnitude is re-solved along the clamped direction D so
  // that the normal condition holds exactly: J = j (n + mu D), n.(v_free + K J) = 0 (the
  // notes' sliding impulse with -T = D)
  const double limit = friction * jn;
  if (jt.squaredNorm() <= limit * limit) return jn * n + jt;
  const double length = jt.norm();
  const Vec3 direction = n + friction * (jt / length);
  const double denominator = n.dot(K * direction);
  const double j = (target_speed - n.dot(v - K * total)) / denominator;
  if (denominator > 1e-12 * n.dot(K * n) && j > 0.0) return j * direction;
  return jn * n + jt * (limit / length);
}

}  // namespace simbake
