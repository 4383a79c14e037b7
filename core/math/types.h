// Basic types shared by every part of the core: Eigen vectors, quaternions and the
// row-major point/triangle arrays that map one to one onto numpy (n x 3) arrays.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cstdint>

namespace simbake {

using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;
using Quat = Eigen::Quaterniond;  // unit quaternion; Eigen stores (x, y, z, w), we speak [w, x, y, z]
using Box3 = Eigen::AlignedBox3d;

// (n x 3) point coordinates, row-major so a numpy float64 (n, 3) array maps without copying
using Points = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;
// (m x 3) vertex indices of triangles, counter-clockwise seen from outside
using Triangles = Eigen::Matrix<std::int32_t, Eigen::Dynamic, 3, Eigen::RowMajor>;

// Cross-product matrix: skew(a) * b == a.cross(b)
inline Mat3 skew(const Vec3& a) {
  Mat3 m;
  m << 0.0, -a.z(), a.y(),
       a.z(), 0.0, -a.x(),
       -a.y(), a.x(), 0.0;
  return m;
}

// Rotation by the rotation vector w (axis * angle), exact for any angle
inline Quat quat_from_rotation_vector(const Vec3& w) {
  const double angle = w.norm();
  if (angle < 1e-300) return Quat::Identity();
  return Quat(Eigen::AngleAxisd(angle, w / angle));
}

// Inverse of quat_from_rotation_vector, taking the shorter way round
inline Vec3 rotation_vector_from_quat(Quat q) {
  if (q.w() < 0.0) q.coeffs() = -q.coeffs();
  const Vec3 v = q.vec();
  const double s = v.norm();
  if (s < 1e-300) return Vec3::Zero();
  const double angle = 2.0 * std::atan2(s, q.w());
  return v * (angle / s);
}

// The rotation by the rotation vector phi (angle t = |phi|) and, when asked, its left
// Jacobian: exp(phi + d) = exp(J d) exp(phi) to first order in d, J = I + (1 - cos t) / t^2
// [phi]x + (t - sin t) / t^3 [phi]x^2; from one sine and cosine of t / 2
inline Quat rotation_and_jacobian(const Vec3& phi, Mat3* jacobian) {
  const double t2 = phi.squaredNorm();
  const double t = std::sqrt(t2);
  const double s = std::sin(0.5 * t), c = std::cos(0.5 * t);
  const Quat q = t < 1e-300 ? Quat::Identity() : Quat(c, s * phi.x() / t, s * phi.y() / t, s * phi.z() / t);
  if (jacobian) {
    double a, b;  // (1 - cos t) / t^2 = 2 s^2 / t^2 and (t - sin t) / t^3, by their series near 0
    if (t2 < 1e-8) {
      a = 0.5 - t2 / 24.0;
      b = 1.0 / 6.0 - t2 / 120.0;
    } else {
      a = 2.0 * s * s / t2;
      b = (t - 2.0 * s * c) / (t2 * t);
    }
    const Mat3 k = skew(phi);
    *jacobian = Mat3::Identity() + a * k + b * (k * k);
  }
  return q;
}
inline Mat3 left_jacobian(const Vec3& phi) {
  Mat3 jacobian;
  rotation_and_jacobian(phi, &jacobian);
  return jacobian;
}

}  // namespace simbake
