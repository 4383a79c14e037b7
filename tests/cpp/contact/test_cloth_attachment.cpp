// Cloth points attached to a body (contact/cloth_attachment.h): carried by a keyed body's
// pose and by a deforming surface exactly, against closed forms; a dynamic body carrying a
// cloth keeps the total momentum and angular momentum of the two.
#include "test_support.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace simbake {
namespace {

using test::box_body;
using test::grid_cloth;

Vec3 row(const Points& x, int k) { return x.row(k).transpose(); }

// A sheet hanging from a keyed box that moves 0.6 m and turns a quarter turn about y in 1 s:
// its attached row (under the box) is the box's pose applied to where it was in the box's
// frame at the start, at every frame, to round-off; the sheet hanging from it stays within
// its strain limit + 1% at every frame (the attachment's pull is inside the solve), swinging
// down from it
TEST(ClothAttachment, RidesAKeyedBodyExactly) {
  World world;
  BodyDesc box = box_body(Vec3(0.4, 0.4, 0.4), 1.0, Vec3(0.0, 1.0, 0.0));
  box.kinematic = true;
  const int b = world.add_body(box);
  const Quat turned(Eigen::AngleAxisd(0.5 * M_PI, Vec3::UnitY()));
  world.set_kinematic_track(b, KinematicTrack({0.0, 1.0}, {Vec3(0.0, 1.0, 0.0), Vec3(0.6, 1.1, 0.0)},
                                              {Quat::Identity(), turned}));
  // 9 x 13 vertices, 0.4 x 0.6 m, its row j = 0 along the box's bottom -z edge, 5 mm under it
  ClothDesc sheet = test::with_contacts(grid_cloth(9, 13, 0.4, 0.6, Vec3(-0.2, 0.795, -0.2)), 0.3, 0.005);
  for (int i = 0; i < 9; ++i) sheet.attached.push_back(i);
  const int c = world.add_cloth(sheet);
  world.attach_cloth(c, b);
  std::vector<Vec3> local;
  for (int i = 0; i < 9; ++i) local.push_back(world.body_mesh_pose(b).apply_inverse(row(world.cloth(c).positions(), i)));
  double worst = 0.0, strain = 0.0, lowest = 1.0;
  for (int f = 0; f < 36; ++f) {
    world.step_frame(1.0 / 24.0);
    const Pose pose = world.body_mesh_pose(b);
    for (int i = 0; i < 9; ++i) worst = std::max(worst, (row(world.cloth(c).positions(), i) - pose.apply(local[i])).norm());
    strain = std::max(strain, world.cloth(c).max_strain());
    lowest = std::min(lowest, world.cloth(c).positions().col(1).minCoeff());
  }
  std::printf("  attached row off the box's pose: %.3g m; largest strain %.4f; lowest point %.3f m\n", worst, strain,
              lowest);
  EXPECT_LT(worst, 1e-12);
  EXPECT_LE(strain, 0.1 * 1.01);
  // and it swings from the row as a hinged sheet: down to within 0.1 m of its full 0.6 m below it
  EXPECT_LT(lowest, 0.795 - 0.5);
}

// A sphere mesh that swells (r from 0.3 to 0.4 m) and turns (a quarter turn about y) over
// 24 frames, a collar attached at five of its vertices, each 10 mm out along the radius: a
// point bound at a vertex with an offset along the normal is carried to r(t) R(t) u + 10 mm
// R(t) u (the triangle's frame turns with the sphere, and a uniform swelling keeps its
// directions), to 1e-9 m at every frame
TEST(ClothAttachment, RidesADeformingSurface) {
  World world;
  const TriangleMesh unit = make_sphere_mesh(1.0, 4);
  const auto at = [&](int frame, Points& vertices) {
    const double s = frame / 24.0, r = 0.3 + 0.1 * s;
    const Mat3 R = Eigen::AngleAxisd(0.5 * M_PI * s, Vec3::UnitY()).toRotationMatrix();
    vertices = r * unit.vertices * R.transpose();
    return std::make_pair(r, R);
  };
  Points start;
  at(0, start);
  const int b = world.add_body(test::deforming_sphere_body(start, unit.triangles, 0.3));
  world.set_deforming_frame(b, start, std::make_shared<SphereDistance>(0.3), 1.0 / 24.0);
  // five vertices of the upper half, far apart; the collar: them pushed out 10 mm, then two
  // rows flaring out and down from them
  std::vector<int> ring;
  for (int k = 0; k < unit.vertices.rows() && ring.size() < 5; ++k) {
    const Vec3 u = row(unit.vertices, k);
    if (u.y() > 0.3 && u.y() < 0.8 && std::all_of(ring.begin(), ring.end(), [&](int j) { return (row(unit.vertices, j) - u).norm() > 0.3; })) {
      ring.push_back(k);
    }
  }
  ASSERT_EQ(ring.size(), 5u);
  std::sort(ring.begin(), ring.end(), [&](int a, int c) {
    return std::atan2(unit.vertices(a, 2), unit.vertices(a, 0)) < std::atan2(unit.vertices(c, 2), unit.vertices(c, 0));
  });
  const double d = 0.01;
  ClothDesc collar;
  collar.rest.resize(15, 3);
  for (int i = 0; i < 5; ++i) {
    const Vec3 u = row(unit.vertices, ring[i]);
    for (int j = 0; j < 3; ++j) collar.rest.row(j * 5 + i) = ((0.3 + d + 0.08 * j) * u - Vec3(0.0, 0.08 * j, 0.0)).transpose();
  }
  collar.triangles.resize(16, 3);
  for (int j = 0, t = 0; j < 2; ++j) {
    for (int i = 0; i < 4; ++i) {
      const int p = j * 5 + i;
      collar.triangles.row(t++) << p, p + 5, p + 6;
      collar.triangles.row(t++) << p, p + 6, p + 1;
    }
  }
  collar.attached = {0, 1, 2, 3, 4};
  collar.self_collision = false;
  const int c = world.add_cloth(collar);
  world.attach_cloth(c, b);
  double worst = 0.0;
  for (int f = 1; f <= 24; ++f) {
    Points vertices;
    const auto [r, R] = at(f, vertices);
    world.set_deforming_frame(b, vertices, std::make_shared<SphereDistance>(r), 1.0 / 24.0);
    world.step_frame(1.0 / 24.0);
    for (int i = 0; i < 5; ++i) {
      const Vec3 expected = (r + d) * (R * row(unit.vertices, ring[i]));
      worst = std::max(worst, (row(world.cloth(c).positions(), i) - expected).norm());
    }
  }
  std::printf("  attached collar off the swelling, turning sphere: %.3g m\n", worst);
  EXPECT_LT(worst, 1e-9);
}

// A 2 kg box thrown at 1 m/s and spinning at 2 rad/s, with no gravity, drags a 0.06 kg sheet
// attached along one edge (bound 0.3 m under the box, in its frame, so that the sheet never
// touches it): the sheet's pull slows it, and the total momentum and angular momentum (about
// the origin) of the box and the sheet stay what they were, to round-off (the box takes what
// the attachment gave the sheet)
TEST(ClothAttachment, ADynamicBodyTakesTheReaction) {
  WorldSettings settings;
  settings.gravity = Vec3::Zero();
  settings.sleep_time = 0.0;
  World world(settings);
  BodyDesc box = box_body(Vec3(0.4, 0.4, 0.4), 2.0, Vec3(0.0, 1.0, 0.0));
  box.linear_velocity = Vec3(1.0, 0.0, 0.0);
  box.angular_velocity = Vec3(0.0, 2.0, 0.0);
  const int b = world.add_body(box);
  ClothDesc sheet = test::with_contacts(grid_cloth(7, 9, 0.4, 0.6, Vec3(-0.2, 0.5, -0.2)), 0.3, 0.005);
  sheet.area_density = 0.25;
  for (int i = 0; i < 7; ++i) sheet.attached.push_back(i);
  const int c = world.add_cloth(sheet);
  world.attach_cloth(c, b);
  const auto momenta = [&] {
    const RigidBodyState s = world.body_state(b);
    const double m = 1.0 / world.body_def(b).inverse_mass;
    Vec3 p = m * s.v, l = s.l + s.x.cross(m * s.v);
    const Cloth& cloth = world.cloth(c);
    for (int k = 0; k < cloth.vertex_count(); ++k) {
      const Vec3 pk = cloth.masses()[k] * row(cloth.velocities(), k);
      p += pk;
      l += row(cloth.positions(), k).cross(pk);
    }
    return std::make_pair(p, l);
  };
  // (the sheet starts at rest: its attached row takes the box's velocity at the first step)
  const auto [p0, l0] = momenta();
  for (int f = 0; f < 24; ++f) world.step_frame(1.0 / 24.0);
  const auto [p1, l1] = momenta();
  std::printf("  box %.4f m/s after 1 s (1 at the start); momentum off by %.2g, angular momentum by %.2g\n",
              world.body_state(b).v.x(), (p1 - p0).norm() / p0.norm(), (l1 - l0).norm() / l0.norm());
  EXPECT_LT(world.body_state(b).v.x(), 0.99);
  EXPECT_LT((p1 - p0).norm(), 1e-9 * p0.norm());
  EXPECT_LT((l1 - l0).norm(), 1e-9 * l0.norm());
}

// Bad attachments are refused: a vertex both pinned and attached, one listed twice, one out
// of range; a cloth with attached vertices steps only once attached; a dynamic body lighter
// than the cloth it would carry (the reaction, a step late, would blow up)
TEST(ClothAttachment, BadAttachmentsAreRefused) {
  {
    World world;
    const int b = world.add_body(box_body(Vec3(0.4, 0.4, 0.4), 0.05, Vec3(0.0, 1.0, 0.0)));
    ClothDesc heavy = grid_cloth(7, 9, 0.4, 0.6, Vec3(-0.2, 0.5, -0.2));
    heavy.area_density = 0.25;  // 0.06 kg
    heavy.attached = {0, 1, 2};
    const int c = world.add_cloth(heavy);
    EXPECT_THROW(world.attach_cloth(c, b), std::invalid_argument);
  }
  ClothDesc sheet = grid_cloth(3, 3, 1.0, 1.0);
  sheet.pinned = {0};
  sheet.attached = {0};
  EXPECT_THROW(World().add_cloth(sheet), std::invalid_argument);
  sheet.pinned.clear();
  sheet.attached = {1, 1};
  EXPECT_THROW(World().add_cloth(sheet), std::invalid_argument);
  sheet.attached = {9};
  EXPECT_THROW(World().add_cloth(sheet), std::invalid_argument);
  sheet.attached = {1};
  World world;
  world.add_cloth(sheet);
  EXPECT_THROW(world.step_frame(1.0 / 24.0), std::logic_error);
}

}  // namespace
}  // namespace simbake
