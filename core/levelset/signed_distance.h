// Signed distance functions in a body's own (mesh) frame: negative inside, positive outside.
//
// The rigid and cloth solvers only see this interface. Analytic primitives (sphere, box,
// plane) answer exactly and need no grid; meshes are baked into an OpenVDB grid
// (vdb_levelset.h). Normals are the normalized gradient of phi, in the same frame; callers
// rotate them into world space with the body's orientation.
#pragma once

#include "math/types.h"

#include <algorithm>
#include <limits>
#include <memory>

namespace simbake {

class SignedDistance {
 public:
  virtual ~SignedDistance() = default;
  // phi(p) (m), negative inside
  virtual double phi(const Vec3& p) const = 0;
  // phi(p) and the unit outward normal at p; the normal is always a unit vector
  virtual double phi_and_normal(const Vec3& p, Vec3& normal) const = 0;
  // no two points' phi differ by more than this times their distance (1 for a distance)
  virtual double lipschitz() const { return 1.0; }
  // box that contains the whole zero level set (the solid)
  virtual Box3 bounds() const = 0;
  // how far outside the surface phi and the normal are still the distance and its gradient
  // (m): everywhere for the analytic shapes, the exterior band less a voxel for a grid
  virtual double exterior_reach() const { return std::numeric_limits<double>::infinity(); }
};

using SignedDistancePtr = std::shared_ptr<const SignedDistance>;

// Sphere of radius r centred at the origin
class SphereDistance final : public SignedDistance {
 public:
  explicit SphereDistance(double radius);
  double phi(const Vec3& p) const override;
  double phi_and_normal(const Vec3& p, Vec3& normal) const override;
  Box3 bounds() const override;
  double radius() const { return radius_; }  // (m)

 private:
  double radius_;  // (m)
};

// Axis-aligned box with the given full edge lengths, centred at the origin
class BoxDistance final : public SignedDistance {
 public:
  explicit BoxDistance(const Vec3& size);
  double phi(const Vec3& p) const override;
  double phi_and_normal(const Vec3& p, Vec3& normal) const override;
  Box3 bounds() const override;
  const Vec3& half() const { return half_; }  // half edge lengths (m)

 private:
  Vec3 half_;  // half edge lengths (m)
};

// Half space below the plane y = height (the ground); bounds are infinite below it
class PlaneDistance final : public SignedDistance {
 public:
  explicit PlaneDistance(double height);
  double phi(const Vec3& p) const override;
  double phi_and_normal(const Vec3& p, Vec3& normal) const override;
  Box3 bounds() const override;

 private:
  double height_;  // (m)
};

// The surface between two level sets of one deforming collider: phi = (1 - s) phi0 + s phi1,
// s in [0, 1] (inside a frame: the level sets baked from the frame's start and end meshes).
// A surface that moves by d between them has its zero set moved by s d to first order, and
// exactly for a sphere swelling about a fixed centre (phi = |x| - r is linear in r); where the
// two are further apart than their bands reach it is no longer a distance, so a frame's motion
// must stay within the bands (a few voxels). The normal is the blend's gradient, normalized
class BlendedDistance final : public SignedDistance {
 public:
  BlendedDistance(SignedDistancePtr start, SignedDistancePtr end, double s);
  double phi(const Vec3& p) const override;
  double phi_and_normal(const Vec3& p, Vec3& normal) const override;
  Box3 bounds() const override;  // both surfaces'
  double exterior_reach() const override;
  double lipschitz() const override { return std::max(start_->lipschitz(), end_->lipschitz()); }
  double blend() const { return s_; }

 private:
  SignedDistancePtr start_, end_;
  double s_;  // 0: the start's surface, 1: the end's
};

}  // namespace simbake
