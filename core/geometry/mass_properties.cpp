// Mass properties by summing signed tetrahedra (origin, a, b, c) over the surface triangles.
//
// For the tetrahedron with edge matrix A = [a b c] and d = det(A) = a . (b x c):
//   volume      V_t = d / 6
//   first moment    = V_t (a + b + c) / 4
//   second moment C_t = integral of x x^T dV = d / 120 (a a^T + b b^T + c c^T + s s^T), s = a + b + c
// (the canonical tetrahedron's covariance is (I + 1 1^T) / 120, mapped through A).
// Summed over a closed mesh the parts outside the solid cancel. Moving C to the centre of
// mass gives C' = C - V c c^T, and the inertia tensor is I = trace(C') Id - C'.
#include "geometry/mass_properties.h"

#include <cmath>
#include <stdexcept>

namespace simbake {

MassProperties mass_properties(const TriangleMesh& mesh) {
  double volume = 0.0;
  Vec3 first = Vec3::Zero();
  Mat3 second = Mat3::Zero();
  for (Eigen::Index t = 0; t < mesh.triangles.rows(); ++t) {
    const Vec3 a = mesh.vertices.row(mesh.triangles(t, 0));
    const Vec3 b = mesh.vertices.row(mesh.triangles(t, 1));
    const Vec3 c = mesh.vertices.row(mesh.triangles(t, 2));
    const double d = a.dot(b.cross(c));
    const Vec3 s = a + b + c;
    volume += d / 6.0;
    first += (d / 24.0) * s;
    second += (d / 120.0) * (a * a.transpose() + b * b.transpose() + c * c.transpose() + s * s.transpose());
  }
  if (!(volume > 0.0)) {
    throw std::invalid_argument("mesh encloses no positive volume (open, flat or inside out)");
  }
  MassProperties props;
  props.volume = volume;
  props.center = first / volume;
  const Mat3 central = second - volume * props.center * props.center.transpose();
  props.inertia = central.trace() * Mat3::Identity() - central;
  return props;
}

MassProperties sphere_mass_properties(double radius) {
  MassProperties props;
  props.volume = 4.0 / 3.0 * M_PI * radius * radius * radius;
  props.inertia = (0.4 * props.volume * radius * radius) * Mat3::Identity();
  return props;
}

MassProperties box_mass_properties(const Vec3& size) {
  MassProperties props;
  props.volume = size.prod();
  const Vec3 sq = size.cwiseAbs2();
  props.inertia = (props.volume / 12.0 * Vec3(sq.y() + sq.z(), sq.x() + sq.z(), sq.x() + sq.y())).asDiagonal();
  return props;
}

}  // namespace simbake
