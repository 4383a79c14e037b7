// Meshes and mass properties against analytic values.
#include <gtest/gtest.h>

#include "geometry/mass_properties.h"
#include "geometry/mesh.h"

#include <cmath>

using namespace simbake;

TEST(Mesh, SphereFromProjectedCube) {
  for (int s : {1, 4, 9}) {
    const TriangleMesh mesh = make_sphere_mesh(2.0, s);
    EXPECT_EQ(mesh.vertices.rows(), 6 * s * s + 2);
    EXPECT_EQ(mesh.triangles.rows(), 12 * s * s);
    EXPECT_TRUE(is_closed(mesh));
    for (Eigen::Index v = 0; v < mesh.vertices.rows(); ++v) EXPECT_NEAR(mesh.vertices.row(v).norm(), 2.0, 1e-12);
  }
}

TEST(Mesh, BoxIsClosedWithExactCorners) {
  const TriangleMesh mesh = make_box_mesh(Vec3(1.0, 2.0, 3.0), 3);
  EXPECT_TRUE(is_closed(mesh));
  EXPECT_EQ(mesh.vertices.rows(), 6 * 9 + 2);
  EXPECT_NEAR(mesh.vertices.col(0).maxCoeff(), 0.5, 1e-15);
  EXPECT_NEAR(mesh.vertices.col(1).minCoeff(), -1.0, 1e-15);
  EXPECT_NEAR(mesh.vertices.col(2).maxCoeff(), 1.5, 1e-15);
}

TEST(Mesh, SubdivisionsAreBoundedBeforeAllocating) {
  for (int s : {0, kMaxSubdivisions + 1, 2147483647}) {
    EXPECT_THROW(make_box_mesh(Vec3::Ones(), s), std::invalid_argument) << s;
    EXPECT_THROW(make_sphere_mesh(1.0, s), std::invalid_argument) << s;
  }
}

TEST(Mesh, OpenMeshIsNotClosed) {
  TriangleMesh mesh = make_box_mesh(Vec3::Ones(), 1);
  mesh.triangles.conservativeResize(mesh.triangles.rows() - 1, 3);
  EXPECT_FALSE(is_closed(mesh));
  EXPECT_THROW(mass_properties(TriangleMesh{mesh.vertices, Triangles(0, 3)}), std::invalid_argument);
}

TEST(Mesh, VertexNormalsAreRadialOnASphereAndStartFromZero) {
  const TriangleMesh mesh = make_sphere_mesh(1.0, 16);
  const Points first = vertex_normals(mesh);
  const Points second = vertex_normals(mesh);
  EXPECT_EQ(first, second);  // no leftover state: accumulated from zero every time
  double worst = 0.0;
  for (Eigen::Index v = 0; v < mesh.vertices.rows(); ++v) {
    EXPECT_NEAR(first.row(v).norm(), 1.0, 1e-12);
    worst = std::max(worst, std::acos(std::min(1.0, first.row(v).dot(mesh.vertices.row(v)))));
  }
  // the area-weighted average of the faces around a vertex of a 16x16 projected cube is
  // within a few degrees of the true radial normal (largest at the cube's corners)
  EXPECT_LT(worst * 180.0 / M_PI, 3.0);
  // an unused vertex gets +y, not garbage
  TriangleMesh with_loose = mesh;
  with_loose.vertices.conservativeResize(mesh.vertices.rows() + 1, 3);
  with_loose.vertices.row(mesh.vertices.rows()) << 5.0, 5.0, 5.0;
  const Points loose = vertex_normals(with_loose);
  EXPECT_EQ(Vec3(loose.row(mesh.vertices.rows())), Vec3::UnitY());
}

TEST(MassProperties, BoxMeshIsExact) {
  const Vec3 size(1.0, 2.0, 3.0);
  const MassProperties mesh = mass_properties(make_box_mesh(size, 2));
  const MassProperties exact = box_mass_properties(size);
  EXPECT_NEAR(mesh.volume, 6.0, 1e-12);
  EXPECT_NEAR(mesh.center.norm(), 0.0, 1e-12);
  EXPECT_TRUE(mesh.inertia.isApprox(exact.inertia, 1e-12));
  // I_xx = V (b^2 + c^2) / 12 by hand
  EXPECT_NEAR(exact.inertia(0, 0), 6.0 * (4.0 + 9.0) / 12.0, 1e-12);
}

TEST(MassProperties, MovedAndTurnedBoxKeepsItsInertiaAboutTheCentre) {
  TriangleMesh mesh = make_box_mesh(Vec3(1.0, 2.0, 3.0), 1);
  const Mat3 R = Eigen::AngleAxisd(0.7, Vec3(1, 2, 3).normalized()).toRotationMatrix();
  const Vec3 t(4.0, -5.0, 6.0);
  for (Eigen::Index v = 0; v < mesh.vertices.rows(); ++v) {
    mesh.vertices.row(v) = (R * Vec3(mesh.vertices.row(v)) + t).transpose();
  }
  const MassProperties props = mass_properties(mesh);
  EXPECT_TRUE(props.center.isApprox(t, 1e-12));
  const Mat3 expected = R * box_mass_properties(Vec3(1.0, 2.0, 3.0)).inertia * R.transpose();
  EXPECT_TRUE(props.inertia.isApprox(expected, 1e-10));
}

TEST(MassProperties, SphereMeshConvergesToAnalytic) {
  // the inscribed polyhedron misses a volume proportional to h^2 (h ~ 1/s): halving h must
  // cut the error by about 4
  const MassProperties exact = sphere_mass_properties(1.0);
  double previous = 0.0;
  for (int s : {8, 16, 32}) {
    const MassProperties props = mass_properties(make_sphere_mesh(1.0, s));
    const double volume_error = std::abs(props.volume - exact.volume) / exact.volume;
    const double inertia_error = (props.inertia - exact.inertia).norm() / exact.inertia.norm();
    EXPECT_LT(inertia_error, 3.0 * volume_error);
    EXPECT_LT(props.center.norm(), 1e-12);
    if (previous > 0.0) {
      EXPECT_GT(previous / volume_error, 3.5);
    }
    previous = volume_error;
  }
  EXPECT_LT(previous, 2e-3);
}
