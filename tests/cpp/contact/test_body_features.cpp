// A body's corners and edges against cloth triangles (contact/body_features.h): the feature
// points of a box and of meshes and the feature-triangle test against hand-computed answers,
// and a box's corner, a mesh cube's corner and a mesh wedge's edge pushed into a taut sheet,
// whose edges must never cross a cloth triangle (checked with a segment-triangle test written
// here); without the mesh's features (the level set alone) the mesh bodies do cross it.
#include <gtest/gtest.h>

#include "contact/body_features.h"
#include "geometry/mass_properties.h"
#include "geometry/mesh.h"
#include "levelset/signed_distance.h"
#include "levelset/vdb_levelset.h"
#include "test_support.h"
#include "world/world.h"

#include <algorithm>
#include <cmath>
#include <random>

using namespace simbake;

// half extents 0.5, spacing 0.25: each 1 m edge in 4 pieces, so 3 inner points per edge and
// the 8 corners: 44 points, all on two faces at once (two coordinates at +-0.5, phi = 0),
// each normal the unit sum of its faces' normals
TEST(BodyFeatures, BoxEdgePointsAndNormals) {
  std::vector<Vec3> points, normals;
  box_edge_features(Vec3::Constant(0.5), 0.25, points, normals);
  ASSERT_EQ(points.size(), 44u);
  const BoxDistance box(Vec3::Constant(1.0));
  for (size_t i = 0; i < points.size(); ++i) {
    EXPECT_NEAR(box.phi(points[i]), 0.0, 1e-15);
    int on_faces = 0;
    Vec3 expected = Vec3::Zero();
    for (int a = 0; a < 3; ++a) {
      if (std::abs(std::abs(points[i][a]) - 0.5) < 1e-15) {
        ++on_faces;
        expected[a] = points[i][a] > 0 ? 1.0 : -1.0;
      }
    }
    EXPECT_GE(on_faces, 2);
    EXPECT_LT((normals[i] - expected.normalized()).norm(), 1e-15);
  }
}

// the triangle (0,0,0), (1,0,0), (0,0,1) in the plane y = 0; h = 5 mm, band 5 cm
TEST(BodyFeatures, FeatureAgainstTriangle) {
  const Vec3 a(0, 0, 0), b(1, 0, 0), c(0, 0, 1), up(0, 1, 0);
  Vec3 w, normal;
  double phi;
  // 3 mm under the plane, facing up: the plane is 3 mm ahead (closer than h); projection at
  // (0.2, 0, 0.3) = 0.5 a + 0.2 b + 0.3 c
  ASSERT_TRUE(feature_against_triangle(Vec3(0.2, -0.003, 0.3), up, a, b, c, 0.005, 0.05, w, normal, phi));
  EXPECT_NEAR(phi, 0.003, 1e-15);
  EXPECT_LT((w - Vec3(0.5, 0.2, 0.3)).norm(), 1e-14);
  EXPECT_LT((normal - up).norm(), 1e-15);
  // 1 cm through the plane: the plane is 1 cm behind it (within the band)
  ASSERT_TRUE(feature_against_triangle(Vec3(0.2, 0.01, 0.3), up, a, b, c, 0.005, 0.05, w, normal, phi));
  EXPECT_NEAR(phi, -0.01, 1e-15);
  // the normal turns towards the feature's: the same feature facing down sees the plane 1 cm ahead
  ASSERT_FALSE(feature_against_triangle(Vec3(0.2, 0.01, 0.3), -up, a, b, c, 0.005, 0.05, w, normal, phi));
  EXPECT_NEAR(phi, 0.01, 1e-15);
  // far under the plane (beyond the band), outside the triangle, far above: none
  EXPECT_FALSE(feature_against_triangle(Vec3(0.2, 0.1, 0.3), up, a, b, c, 0.005, 0.05, w, normal, phi));
  EXPECT_FALSE(feature_against_triangle(Vec3(0.8, -0.001, 0.8), up, a, b, c, 0.005, 0.05, w, normal, phi));
  EXPECT_FALSE(feature_against_triangle(Vec3(0.2, -0.006, 0.3), up, a, b, c, 0.005, 0.05, w, normal, phi));
}

namespace {

// a 1 m sheet of n x n vertices at y = 1 m, centred on the y axis, pinned along its border
ClothDesc bordered_sheet(int n) {
  ClothDesc sheet = test::grid_cloth(n, n, 1.0, 1.0, Vec3(-0.5, 1.0, -0.5));
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      if (i == 0 || j == 0 || i == n - 1 || j == n - 1) sheet.pinned.push_back(j * n + i);
    }
  }
  return sheet;
}

// whether segment (p, q) crosses triangle (a, b, c) strictly (ends on opposite sides of the
// plane, the crossing inside the triangle by barycentric coordinates)
bool segment_crosses(const Vec3& p, const Vec3& q, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 n = (b - a).cross(c - a);
  const double dp = n.dot(p - a), dq = n.dot(q - a);
  if (!((dp > 0 && dq < 0) || (dp < 0 && dq > 0))) return false;
  const Vec3 x = p + (q - p) * (dp / (dp - dq));
  const double area = n.squaredNorm();
  const double u = (b - x).cross(c - x).dot(n) / area, v = (c - x).cross(a - x).dot(n) / area;
  return u > 0 && v > 0 && u + v < 1;
}

}  // namespace

// A 1 m sheet (5 cm edges) pinned along its border, a 20 cm kinematic box turned corner down
// and driven 16 cm down into it at 0.4 m/s, its corner over the inside of a triangle (no
// vertex under it): the corner must push the sheet down (its middle sinks > 5 cm) and no
// box edge may cross a cloth triangle at any step
TEST(BodyFeatures, BoxCornerNeverPokesThroughATautSheet) {
  World world;
  const int n = 21;
  world.add_cloth(test::with_contacts(bordered_sheet(n), 0.3, 0.005, false));
  // the rotation taking the corner (-1, -1, -1) / sqrt(3) to -y
  const Vec3 corner_dir = -Vec3::Ones().normalized();
  const Quat turn = Quat::FromTwoVectors(corner_dir, -Vec3::UnitY());
  BodyDesc box = test::box_body(Vec3::Constant(0.2), 1.0, Vec3::Zero());
  box.kinematic = true;
  box.orientation = turn;
  const Vec3 corner = turn * Vec3::Constant(-0.1);
  box.origin = Vec3(0.0125, 1.04, 0.0175) - corner;
  box.linear_velocity = Vec3(0.0, -0.4, 0.0);
  world.add_body(box);
  std::vector<std::array<Vec3, 2>> edges;
  for (int a = 0; a < 8; ++a) {
    for (int b = a + 1; b < 8; ++b) {
      if (__builtin_popcount(a ^ b) != 1) continue;
      const auto at = [](int k) { return Vec3((k & 1) ? 0.1 : -0.1, (k & 2) ? 0.1 : -0.1, (k & 4) ? 0.1 : -0.1); };
      edges.push_back({at(a), at(b)});
    }
  }
  int crossings = 0;
  for (int step = 0; step < 96; ++step) {  // 0.4 s
    world.step(1.0 / 240.0);
    const Pose pose = mesh_pose(world.body_def(0), world.body_state(0));
    const Points& x = world.cloth(0).positions();
    const Triangles& t = world.cloth(0).triangles();
    for (const auto& e : edges) {
      const Vec3 p = pose.apply(e[0]), q = pose.apply(e[1]);
      for (int k = 0; k < t.rows(); ++k) {
        crossings += segment_crosses(p, q, x.row(t(k, 0)).transpose(), x.row(t(k, 1)).transpose(),
                                     x.row(t(k, 2)).transpose());
      }
    }
  }
  EXPECT_LT(world.cloth(0).positions()((n / 2) * n + n / 2, 1), 0.95);
  EXPECT_EQ(crossings, 0);
}

// a cube mesh of side 1 whose faces are split 2 x 2 has the same features as the box at
// spacing 0.25: each mesh edge along the cube's edges (0.5 long) gives its midpoint, the
// cube's 8 corners and the 12 vertices halfway along its edges are corners; the faces' inner
// edges and their centre vertices are flat (none). Normals: the unit sum of the faces there
TEST(BodyFeatures, MeshCubeHasTheBoxFeatures) {
  const TriangleMesh cube = make_box_mesh(Vec3::Ones(), 2);
  std::vector<Vec3> points, normals, box_points, box_normals;
  mesh_edge_features(cube.vertices, cube.triangles, 0.25, sharp_crease_angle(0.005, 0.05), points, normals);
  box_edge_features(Vec3::Constant(0.5), 0.25, box_points, box_normals);
  ASSERT_EQ(points.size(), 44u);
  ASSERT_EQ(box_points.size(), 44u);
  for (size_t i = 0; i < points.size(); ++i) {
    size_t match = box_points.size();
    for (size_t j = 0; j < box_points.size(); ++j) {
      if ((points[i] - box_points[j]).norm() < 1e-12) match = j;
    }
    ASSERT_LT(match, box_points.size()) << points[i].transpose();
    EXPECT_LT((normals[i] - box_normals[match]).norm(), 1e-12) << points[i].transpose();
  }
}

// the threshold: 2 atan(h / 2L), at most 30 degrees; a fine sphere mesh (16 subdivisions,
// creases of a few degrees) has no feature at 30 degrees, and at 0 every vertex is a corner
TEST(BodyFeatures, SharpCreaseAngle) {
  EXPECT_NEAR(sharp_crease_angle(0.005, 0.05), 2.0 * std::atan(0.05), 1e-15);
  EXPECT_NEAR(sharp_crease_angle(0.01, 0.01), M_PI / 6.0, 1e-15);
  const TriangleMesh sphere = make_sphere_mesh(0.25, 16);
  std::vector<Vec3> points, normals;
  mesh_edge_features(sphere.vertices, sphere.triangles, 1.0, M_PI / 6.0, points, normals);
  EXPECT_EQ(points.size(), 0u);
  mesh_edge_features(sphere.vertices, sphere.triangles, 1.0, 0.0, points, normals);
  // spacing 1 m: no inner points, every vertex is a corner (its normal the sphere's)
  ASSERT_EQ(points.size(), static_cast<size_t>(sphere.vertices.rows()));
  for (size_t i = 0; i < points.size(); ++i) EXPECT_LT((normals[i] - points[i].normalized()).norm(), 0.05);
}

namespace {

// A wedge (a prism of triangular section) of length `length` along x, its sharp edge along
// the x axis at the origin, its two sides opening upwards at `angle` (rad) between them to a
// top face at height `height`, counter-clockwise from outside
TriangleMesh wedge_mesh(double length, double height, double angle) {
  const double w = height * std::tan(0.5 * angle), l = 0.5 * length;
  TriangleMesh m;
  m.vertices.resize(6, 3);
  m.vertices << -l, 0, 0, -l, height, -w, -l, height, w,  //
      l, 0, 0, l, height, -w, l, height, w;
  m.triangles.resize(8, 3);
  m.triangles << 0, 2, 1,  // -x end
      3, 4, 5,             // +x end
      0, 1, 4, 0, 4, 3,    // the -z side
      0, 3, 5, 0, 5, 2,    // the +z side
      1, 2, 5, 1, 5, 4;    // the top
  // orient each face outwards (from the centroid)
  const Vec3 centre = m.vertices.colwise().mean().transpose();
  for (int t = 0; t < 8; ++t) {
    const Vec3 a = m.vertices.row(m.triangles(t, 0)), b = m.vertices.row(m.triangles(t, 1)),
               c = m.vertices.row(m.triangles(t, 2));
    if ((b - a).cross(c - a).dot(a - centre) < 0.0) std::swap(m.triangles(t, 1), m.triangles(t, 2));
  }
  return m;
}

// A kinematic body made from a closed mesh's level set (voxel `voxel`), with the mesh for its
// features or without it (the level set alone, as before mesh features)
BodyDesc mesh_body(const TriangleMesh& mesh, double voxel, bool with_mesh) {
  BodyDesc d;
  d.shape = VdbLevelSet::bake(mesh.vertices, mesh.triangles, voxel);
  d.samples = mesh.vertices;
  d.unit_mass = mass_properties(mesh);
  d.kinematic = true;
  if (with_mesh) {
    d.mesh_vertices = mesh.vertices;
    d.mesh_triangles = mesh.triangles;
  }
  return d;
}

struct SheetRun {
  int crossings = 0;        // (mesh edge, cloth triangle, step) crossings
  double middle_y = 0.0;    // the sheet's middle vertex at the end (m)
};

// The box test's setup with a mesh body: a 1 m sheet (5 cm edges, h = 5 mm) pinned along its
// border, the body (already placed and moving) driven into it for 0.4 s at 240 steps per
// second; every edge of the body's mesh against every cloth triangle at every step
SheetRun drive_into_sheet(const BodyDesc& body, const TriangleMesh& mesh) {
  World world;
  const int n = 21;
  world.add_cloth(test::with_contacts(bordered_sheet(n), 0.3, 0.005, false));
  world.add_body(body);
  SheetRun run;
  const auto edges = unique_edges(mesh.triangles);
  for (int step = 0; step < 96; ++step) {
    world.step(1.0 / 240.0);
    const Pose pose = mesh_pose(world.body_def(0), world.body_state(0));
    const Points& x = world.cloth(0).positions();
    const Triangles& t = world.cloth(0).triangles();
    for (const auto& e : edges) {
      const Vec3 p = pose.apply(mesh.vertices.row(e[0]).transpose()), q = pose.apply(mesh.vertices.row(e[1]).transpose());
      for (int k = 0; k < t.rows(); ++k) {
        run.crossings += segment_crosses(p, q, x.row(t(k, 0)).transpose(), x.row(t(k, 1)).transpose(),
                                         x.row(t(k, 2)).transpose());
      }
    }
  }
  run.middle_y = world.cloth(0).positions()((n / 2) * n + n / 2, 1);
  return run;
}

}  // namespace

// The box test's corner with a mesh cube (20 cm, its level set at 5 mm voxels): with its
// features no edge crosses the sheet while it is pushed down over 5 cm; from the level set
// alone (its rounded corner, cloth vertices and edge points held out of it) the corner goes
// through the inside of a triangle (measured: 0 crossings and the middle at 0.868 m with the
// features; 348 (edge, triangle, step) crossings without)
TEST(BodyFeatures, MeshCubeCornerNeverPokesThroughATautSheet) {
  const TriangleMesh cube = make_box_mesh(Vec3::Constant(0.2), 1);
  const Quat turn = Quat::FromTwoVectors(-Vec3::Ones().normalized(), -Vec3::UnitY());
  const Vec3 corner = turn * Vec3::Constant(-0.1);
  SheetRun runs[2];
  for (bool with_mesh : {true, false}) {
    BodyDesc body = mesh_body(cube, 0.005, with_mesh);
    body.orientation = turn;
    body.origin = Vec3(0.0125, 1.04, 0.0175) - corner;
    body.linear_velocity = Vec3(0.0, -0.4, 0.0);
    runs[with_mesh] = drive_into_sheet(body, cube);
  }
  EXPECT_LT(runs[1].middle_y, 0.95);
  EXPECT_EQ(runs[1].crossings, 0);
  EXPECT_GT(runs[0].crossings, 0);
}

// A wedge's sharp edge (60 degrees between its sides, 40 cm long), turned 30 degrees about
// the vertical so that it runs across the cloth's triangles, not along their edges, pushed
// down into the sheet: with its features (the edge every 1.25 cm) no edge of it crosses a
// cloth triangle and the sheet goes down with it; from the level set alone it cuts through
// (measured: 0 crossings, the middle at 0.858 m; 956 crossings without)
TEST(BodyFeatures, MeshWedgeEdgeNeverCutsThroughATautSheet) {
  const TriangleMesh wedge = wedge_mesh(0.4, 0.15, M_PI / 3.0);
  std::vector<Vec3> points, normals;
  mesh_edge_features(wedge.vertices, wedge.triangles, 0.0125, sharp_crease_angle(0.005, 0.05), points, normals);
  // its ends are equilateral triangles of side 17.3 cm: 3 edges of 40 cm along x (32 pieces:
  // 31 inner points each), 6 of 17.3 cm (14 pieces: 13 inner points), the rectangles'
  // diagonals flat (none), and the 6 corners
  EXPECT_EQ(points.size(), 3u * 31 + 6 * 13 + 6);
  int on_sharp_edge = 0;
  for (size_t i = 0; i < points.size(); ++i) {
    if (points[i].y() == 0.0 && points[i].z() == 0.0) {
      ++on_sharp_edge;
      // straight down, between the two sides (inner points; the corners lean out of the ends)
      if (std::abs(points[i].x()) < 0.2 - 1e-9) EXPECT_LT((normals[i] + Vec3::UnitY()).norm(), 1e-12);
    }
  }
  EXPECT_EQ(on_sharp_edge, 31 + 2);
  const Quat turn(Eigen::AngleAxisd(M_PI / 6.0, Vec3::UnitY()));
  SheetRun runs[2];
  for (bool with_mesh : {true, false}) {
    BodyDesc body = mesh_body(wedge, 0.005, with_mesh);
    body.orientation = turn;
    body.origin = Vec3(0.0125, 1.03, 0.0175);
    body.linear_velocity = Vec3(0.0, -0.4, 0.0);
    runs[with_mesh] = drive_into_sheet(body, wedge);
  }
  EXPECT_LT(runs[1].middle_y, 0.95);
  EXPECT_EQ(runs[1].crossings, 0);
  EXPECT_GT(runs[0].crossings, 0);
}

// The triangle grid's two layouts (a dense block of buckets filled by counting, and sorted
// entries) list the same triangles in the same order for every point, in and around the
// region; and every triangle whose grown box holds a point of the region is listed for it
// (the grid's promise, checked by a box test written here). Random sheets of triangles of
// edge 0.05 and 0.3 m, cells 0.05 m, regions from a few cells to wider than the sheet,
// shifted by about 2^21 cells so that the wrapped cell names are exercised
TEST(BodyFeatures, TriangleGridLayoutsListTheSameTriangles) {
  std::mt19937 random(7);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (int trial = 0; trial < 40; ++trial) {
    const double cell = 0.05, margin = 0.01, size = trial % 2 ? 0.05 : 0.3;
    const Vec3 offset = trial % 5 == 4 ? Vec3(cell * ((1 << 21) - 3), 0.0, -cell * (1 << 20)) : Vec3::Zero();
    const int count = 300;
    Points x(3 * count, 3);
    Triangles triangles(count, 3);
    for (int t = 0; t < count; ++t) {
      const Vec3 corner = offset + Vec3(2.0 * unit(random), 0.5 * unit(random), 2.0 * unit(random));
      for (int v = 0; v < 3; ++v) {
        x.row(3 * t + v) = (corner + size * Vec3(unit(random), unit(random), unit(random))).transpose();
        triangles(t, v) = 3 * t + v;
      }
    }
    const Vec3 centre = offset + Vec3(2.0 * unit(random), 0.25, 2.0 * unit(random));
    const Vec3 half = Vec3::Constant(0.02 + 1.5 * unit(random));
    const Box3 region(centre - half, centre + half);
    TriangleGrid dense, sorted;
    dense.build(x, triangles, cell, margin, region, nullptr, true);
    sorted.build(x, triangles, cell, margin, region, nullptr, false);
    std::vector<int> a, b;
    for (int q = 0; q < 2000; ++q) {
      // points in the region and up to two cells around it
      const Vec3 p = region.min() - Vec3::Constant(2.0 * cell) +
                     Vec3(unit(random), unit(random), unit(random)).cwiseProduct(region.sizes() + Vec3::Constant(4.0 * cell));
      dense.query(p, a);
      sorted.query(p, b);
      ASSERT_EQ(a, b) << "trial " << trial << " point " << q;
      EXPECT_TRUE(std::is_sorted(a.begin(), a.end()));
      if (!region.contains(p)) continue;
      for (int t = 0; t < count; ++t) {
        Box3 box;
        for (int v = 0; v < 3; ++v) box.extend(Vec3(x.row(triangles(t, v)).transpose()));
        box.min().array() -= margin;
        box.max().array() += margin;
        if (box.contains(p)) EXPECT_TRUE(std::binary_search(a.begin(), a.end(), t)) << "trial " << trial;
      }
    }
  }
}
