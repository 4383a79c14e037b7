// A deforming collider's level set inside a frame (signed_distance.h, BlendedDistance).
#include "levelset/signed_distance.h"

#include <algorithm>

namespace simbake {

BlendedDistance::BlendedDistance(SignedDistancePtr start, SignedDistancePtr end, double s)
    : start_(std::move(start)), end_(std::move(end)), s_(std::clamp(s, 0.0, 1.0)) {}

double BlendedDistance::phi(const Vec3& p) const {
  if (s_ == 0.0) return start_->phi(p);
  if (s_ == 1.0) return end_->phi(p);
  return (1.0 - s_) * start_->phi(p) + s_ * end_->phi(p);
}

double BlendedDistance::phi_and_normal(const Vec3& p, Vec3& normal) const {
  if (s_ == 0.0) return start_->phi_and_normal(p, normal);
  if (s_ == 1.0) return end_->phi_and_normal(p, normal);
  Vec3 n0, n1;
  const double phi = (1.0 - s_) * start_->phi_and_normal(p, n0) + s_ * end_->phi_and_normal(p, n1);
  const Vec3 n = (1.0 - s_) * n0 + s_ * n1;
  const double length = n.norm();
  normal = length > 0.0 ? Vec3(n / length) : n1;  // (opposite normals: the end's)
  return phi;
}

Box3 BlendedDistance::bounds() const { return start_->bounds().merged(end_->bounds()); }

double BlendedDistance::exterior_reach() const { return std::min(start_->exterior_reach(), end_->exterior_reach()); }

}  // namespace simbake
