// A deforming collider's surface inside a frame: the blend of its two level sets and its
// vertices' motion (levelset/deforming_surface.h), against closed forms.
#include "geometry/mesh.h"
#include "levelset/deforming_surface.h"
#include "levelset/signed_distance.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>

namespace simbake {
namespace {

// A sphere swelling about a fixed centre: phi = |x| - r is linear in r, so the blend of the
// start's and the end's level sets is exactly the sphere of the blended radius
TEST(BlendedDistance, IsTheSphereOfTheBlendedRadius) {
  const auto start = std::make_shared<SphereDistance>(0.3);
  const auto end = std::make_shared<SphereDistance>(0.5);
  for (double s : {0.0, 0.25, 0.5, 1.0}) {
    const BlendedDistance blend(start, end, s);
    for (const Vec3& p : {Vec3(0.1, 0.2, 0.3), Vec3(1.0, -0.5, 0.0), Vec3(0.0, 0.45, 0.0)}) {
      const double r = (1.0 - s) * 0.3 + s * 0.5;
      Vec3 n;
      EXPECT_NEAR(blend.phi_and_normal(p, n), p.norm() - r, 1e-15);
      EXPECT_NEAR((n - p.normalized()).norm(), 0.0, 1e-15);
    }
  }
  EXPECT_TRUE(BlendedDistance(start, end, 0.5).bounds().contains(Vec3(0.49, 0.0, 0.0)));
}

// Vertices that swell about a moving centre move on an affine field: the least-squares field
// is that field exactly; each vertex's velocity is its own (end - start) / duration, and the
// velocity at a point is the nearest vertex's
TEST(DeformingSurface, MotionOfASwellingMovingSphere) {
  const TriangleMesh sphere = make_sphere_mesh(1.0, 2);
  const auto shape = std::make_shared<SphereDistance>(1.0);
  const Vec3 c0(0.0, 1.0, 0.0), c1(0.1, 1.0, -0.05);
  const double r0 = 0.4, r1 = 0.5, T = 1.0 / 24.0;
  Points start = (sphere.vertices * r0).rowwise() + c0.transpose();
  Points end = (sphere.vertices * r1).rowwise() + c1.transpose();
  DeformingSurface surface(start, shape, 2.0);
  surface.set_frame(end, shape, 2.0, T);
  EXPECT_DOUBLE_EQ(surface.blend(2.0), 0.0);
  EXPECT_NEAR(surface.blend(2.0 + 0.5 * T), 0.5, 1e-12);  // (t - t0) / T in floating point
  EXPECT_DOUBLE_EQ(surface.blend(3.0), 1.0);
  // v(x) = (r1 - r0) / (r0 T) (x0 - c0) + (c1 - c0) / T for x0 on the start's sphere: at blend
  // s, x = c(s) + r(s) u, so v = (r1 - r0) / (r(s) T) (x - c(s)) + (c1 - c0) / T
  const double s = 0.25;
  const double r = (1 - s) * r0 + s * r1;
  const Vec3 c = (1 - s) * c0 + s * c1;
  Mat3 A;
  Vec3 b;
  surface.affine_motion(s, A, b);
  const Mat3 expected_A = Mat3::Identity() * (r1 - r0) / (r * T);
  EXPECT_LT((A - expected_A).norm(), 1e-9);
  EXPECT_LT((b - ((c1 - c0) / T - expected_A * c)).norm(), 1e-9);
  for (int k = 0; k < surface.vertex_count(); ++k) {
    EXPECT_LT((surface.vertex_velocity(k) - (end.row(k) - start.row(k)).transpose() / T).norm(), 1e-12);
    const Vec3 near = surface.vertex(k, 1.0) + 1e-4 * Vec3(1.0, 1.0, 1.0);
    EXPECT_LT((surface.velocity_at(near) - surface.vertex_velocity(k)).norm(), 1e-12);
  }
  double reach = 0.0;
  for (int k = 0; k < surface.vertex_count(); ++k) {
    reach = std::max({reach, (start.row(k).transpose() - c1).norm(), (end.row(k).transpose() - c1).norm()});
  }
  EXPECT_DOUBLE_EQ(surface.reach(c1), reach);
  EXPECT_GT(reach, r1);  // the start's sphere reaches further from the end's centre
}

// The velocity at a point is its nearest vertex's: near the surface, the nearest within the
// cells about it; far from it (no vertex in those cells), the nearest of all, against a
// search of every vertex (ties: the lower index), at points all around and far outside
TEST(DeformingSurface, VelocityFarFromTheSurfaceIsTheNearestVertexs) {
  const TriangleMesh sphere = make_sphere_mesh(1.0, 2);
  const auto shape = std::make_shared<SphereDistance>(1.0);
  Points start = sphere.vertices * 0.4;
  Points end = start;
  for (Eigen::Index k = 0; k < end.rows(); ++k) end.row(k) *= 1.0 + 0.1 * std::sin(3.0 * k);
  DeformingSurface surface(start, shape, 0.0);
  surface.set_frame(end, shape, 0.0, 0.1);
  int far = 0;
  for (int i = 0; i < 2000; ++i) {
    const double t = 0.37 * i, radius = 0.45 + 3.0 * (i % 50) / 50.0;
    const Vec3 p = radius * Vec3(std::cos(t) * std::sin(1.3 * t), std::sin(t) * std::sin(1.3 * t), std::cos(1.3 * t));
    int best = 0;
    for (int k = 1; k < surface.vertex_count(); ++k) {
      if ((surface.vertex(k, 1.0) - p).squaredNorm() < (surface.vertex(best, 1.0) - p).squaredNorm()) best = k;
    }
    if (radius > 1.5) {
      ++far;
      EXPECT_EQ(surface.velocity_at(p), surface.vertex_velocity(best)) << "at " << p.transpose();
    }
  }
  EXPECT_GT(far, 1000);
}

}  // namespace
}  // namespace simbake
