// Inside and depth in a closed mesh against analytic answers and brute force.
#include <gtest/gtest.h>

#include "geometry/closed_mesh.h"
#include "geometry/closest_points.h"
#include "geometry/mesh.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

using namespace simbake;

namespace {

// The nearest triangle's distance over every triangle, by Ericson's closest point
double brute_distance(const TriangleMesh& mesh, const Vec3& p) {
  double best = std::numeric_limits<double>::infinity();
  for (Eigen::Index t = 0; t < mesh.triangles.rows(); ++t) {
    const Vec3 a = mesh.vertices.row(mesh.triangles(t, 0)), b = mesh.vertices.row(mesh.triangles(t, 1)),
               c = mesh.vertices.row(mesh.triangles(t, 2));
    const Vec3 w = closest_on_triangle(p, a, b, c);
    best = std::min(best, (p - (w.x() * a + w.y() * b + w.z() * c)).norm());
  }
  return best;
}

}  // namespace

TEST(ClosedMesh, BoxInsideAndDepthAreAnalytic) {
  const TriangleMesh box = make_box_mesh(Vec3(1.0, 2.0, 3.0), 3);
  const ClosedMesh mesh(box.vertices, box.triangles);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-2.0, 2.0);
  const Vec3 half(0.5, 1.0, 1.5);
  for (int k = 0; k < 2000; ++k) {
    const Vec3 p(u(rng), u(rng), u(rng));
    const Vec3 gap = half - p.cwiseAbs();           // > 0 on every axis: inside
    if (std::abs(gap.minCoeff()) < 1e-9) continue;  // on the surface
    EXPECT_EQ(mesh.inside(p), gap.minCoeff() > 0) << p.transpose();
    if (gap.minCoeff() > 0) EXPECT_NEAR(mesh.distance(p), gap.minCoeff(), 1e-12) << p.transpose();
    else EXPECT_NEAR(mesh.distance(p), (-gap).cwiseMax(0.0).norm(), 1e-12) << p.transpose();
  }
}

TEST(ClosedMesh, SphereDistanceIsTheNearestTrianglesAnywhere) {
  const TriangleMesh sphere = make_sphere_mesh(1.0, 12);
  const ClosedMesh mesh(sphere.vertices, sphere.triangles);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-3.0, 3.0);
  for (int k = 0; k < 300; ++k) {
    const Vec3 p = k == 0 ? Vec3::Zero() : Vec3(u(rng), u(rng), u(rng));
    EXPECT_NEAR(mesh.distance(p), brute_distance(sphere, p), 1e-12) << p.transpose();
    // inside the inscribed polyhedron's chords (a vertex ring's chord sags under 1% of r)
    const double r = p.norm();
    if (r < 0.98 || r > 1.0) EXPECT_EQ(mesh.inside(p), r < 0.98) << p.transpose();
  }
}

TEST(ClosedMesh, DepthOfPointsAndEdgeEighths) {
  const TriangleMesh box = make_box_mesh(Vec3::Ones(), 2);
  const ClosedMesh mesh(box.vertices, box.triangles);
  Points points(4, 3);
  points << -1.0, 0.1, 0.05,  // an edge through the box, its ends outside
             1.0, 0.1, 0.05,
             0.3, 0.2, 0.1,   // a vertex 0.2 deep, on a short edge inside
             0.4, 0.2, 0.1;
  Edges edges(2, 2);
  edges << 0, 1, 2, 3;
  const ClosedMeshDepth depth = closed_mesh_depth(mesh, points, edges);
  EXPECT_NEAR(depth.vertex, 0.2, 1e-12);
  // the first edge's eighth at its middle: 0.4 from the face at y = 0.5
  EXPECT_NEAR(depth.edge, 0.4, 1e-12);
  EXPECT_EQ(closed_mesh_depth(mesh, points.topRows(2), edges.topRows(1)).vertex, 0.0);
  EXPECT_NEAR(closed_mesh_depth(mesh, points.topRows(2), edges.topRows(1)).edge, 0.4, 1e-12);
  Edges bad(1, 2);
  bad << 0, 4;
  EXPECT_THROW(closed_mesh_depth(mesh, points, bad), std::out_of_range);
}

TEST(ClosedMesh, EmptyMeshHasNothingInside) {
  const ClosedMesh mesh(Points(0, 3), Triangles(0, 3));
  EXPECT_FALSE(mesh.inside(Vec3::Zero()));
  EXPECT_EQ(closed_mesh_depth(mesh, Points::Zero(1, 3), Edges(0, 2)).vertex, 0.0);
}
