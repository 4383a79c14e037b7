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

}  // namespace simbake
