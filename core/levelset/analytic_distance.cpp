// Exact signed distances of the primitives.
#include "levelset/signed_distance.h"

#include <algorithm>
#include <limits>

namespace simbake {

SphereDistance::SphereDistance(double radius) : radius_(radius) {}

double SphereDistance::phi(const Vec3& p) const { return p.norm() - radius_; }

double SphereDistance::phi_and_normal(const Vec3& p, Vec3& normal) const {
  const double r = p.norm();
  // at the centre every direction is as good as any other: pick +y (deterministic)
  normal = r > 0.0 ? Vec3(p / r) : Vec3::UnitY();
  return r - radius_;
}

Box3 SphereDistance::bounds() const {
  return Box3(Vec3::Constant(-radius_), Vec3::Constant(radius_));
}

BoxDistance::BoxDistance(const Vec3& size) : half_(0.5 * size) {}

double BoxDistance::phi(const Vec3& p) const {
  const Vec3 d = p.cwiseAbs() - half_;
  const double outside = d.cwiseMax(0.0).norm();
  const double inside = std::min(d.maxCoeff(), 0.0);
  return outside + inside;
}

double BoxDistance::phi_and_normal(const Vec3& p, Vec3& normal) const {
  const Vec3 d = p.cwiseAbs() - half_;
  const Vec3 sign = p.unaryExpr([](double x) { return x < 0.0 ? -1.0 : 1.0; });
  if (d.maxCoeff() > 0.0) {
    // outside: gradient points from the closest surface point to p
    const Vec3 excess = d.cwiseMax(0.0);
    const double dist = excess.norm();
    normal = excess.cwiseProduct(sign) / dist;
    return dist;
  }
  // inside (or on the surface): the nearest face is the one with the largest d
  Eigen::Index axis = 0;
  const double depth = d.maxCoeff(&axis);
  normal = Vec3::Zero();
  normal[axis] = sign[axis];
  return depth;
}

Box3 BoxDistance::bounds() const { return Box3(-half_, half_); }

PlaneDistance::PlaneDistance(double height) : height_(height) {}

double PlaneDistance::phi(const Vec3& p) const { return p.y() - height_; }

double PlaneDistance::phi_and_normal(const Vec3& p, Vec3& normal) const {
  normal = Vec3::UnitY();
  return p.y() - height_;
}

Box3 PlaneDistance::bounds() const {
  const double inf = std::numeric_limits<double>::infinity();
  return Box3(Vec3(-inf, -inf, -inf), Vec3(inf, height_, inf));
}

}  // namespace simbake
