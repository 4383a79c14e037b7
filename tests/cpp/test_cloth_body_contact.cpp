// A cloth against bodies and the ground (contact/cloth_body_contact.h), without a World: the
// bodies are a plain ContactBodies written here. A free cloth vertex whose candidate x + dt v
// lies inside the ground or a sphere gets the normal velocity change dv_n = (h - phi) / dt,
// which leaves its candidate exactly at the thickness h, and Coulomb friction takes mu dv_n
// off its slip (or stops it); against a dynamic body the cloth's momentum change goes to the
// body, opposite, so their total momentum is unchanged; a sleeping body is woken, not pushed.
#include <gtest/gtest.h>

#include "contact/cloth_body_contact.h"
#include "geometry/closest_points.h"

#include <cmath>
#include <optional>
#include <tuple>
#include <vector>

using namespace simbake;

namespace {

// Bodies as plain arrays: a dynamic body's angular velocity is I^-1 L with a constant I^-1
class PlainBodies final : public ContactBodies {
 public:
  std::vector<ContactBody> bodies;
  std::vector<Vec3> v, l;              // (nbody) linear velocity (m/s), angular momentum (N m s)
  std::vector<Mat3> inverse_inertia_;  // (nbody) world I^-1 (1/(kg m^2))
  std::vector<char> asleep_;
  std::optional<ContactGround> ground_;

  void add(const ContactBody& body, const Mat3& inverse_inertia) {
    bodies.push_back(body);
    v.push_back(Vec3::Zero());
    l.push_back(Vec3::Zero());
    inverse_inertia_.push_back(inverse_inertia);
    asleep_.push_back(0);
  }
  int count() const override { return static_cast<int>(bodies.size()); }
  const ContactBody& body(int b) const override { return bodies[b]; }
  const ContactGround* ground() const override { return ground_ ? &*ground_ : nullptr; }
  bool asleep(int b) const override { return asleep_[b] != 0; }
  void wake(int b) override { asleep_[b] = 0; }
  Vec3 velocity_at(int b, const Vec3& p) const override {
    return v[b] + (inverse_inertia_[b] * l[b]).cross(p - bodies[b].center);
  }
  void apply_impulse(int b, const Vec3& p, const Vec3& J) override {
    v[b] += bodies[b].inverse_mass * J;
    l[b] += (p - bodies[b].center).cross(J);
  }
  Mat3 inverse_inertia(int b) const override { return inverse_inertia_[b]; }
  void displace(int b, const Vec3& velocity, const Vec3&, double dt) override {
    bodies[b].center += dt * velocity;
    bodies[b].pose.translation += dt * velocity;
  }
};

// One triangle: vertex 0 free at `free`, vertices 1 and 2 pinned 1 m above it, so that
// only vertex 0 comes near a surface (its edges' quarter points stay 0.25 m away)
Cloth one_free_vertex(const Vec3& free) {
  ClothDesc desc;
  desc.rest.resize(3, 3);
  desc.rest.row(0) = free.transpose();
  desc.rest.row(1) = (free + Vec3(0.0, 1.0, 0.0)).transpose();
  desc.rest.row(2) = (free + Vec3(1.0, 1.0, 0.0)).transpose();
  desc.triangles.resize(1, 3);
  desc.triangles << 0, 1, 2;
  desc.pinned = {1, 2};
  return Cloth(desc);
}

ContactBody sphere(const SphereDistance& shape, double radius, const Vec3& center, double inverse_mass) {
  ContactBody body;
  body.shape = &shape;
  body.pose.translation = center;
  body.center = center;
  body.bounding_radius = radius;
  body.friction = 0.5;
  body.inverse_mass = inverse_mass;
  body.kinematic = inverse_mass == 0.0;
  body.still = body.kinematic;
  return body;
}

}  // namespace

// On the ground (friction 0.5 each, so mu = 0.5): a vertex at h + dt falling at 2 m/s has its
// candidate at h - dt, phi = h - dt, so dv_n = 1 m/s and it ends the step exactly at h; its
// slip of 3 m/s loses mu dv_n = 0.5 m/s, a slip of 0.3 m/s (under 0.5) stops. At three steps
TEST(ClothBodyContact, GroundStopsAVertexAtTheThicknessWithCoulombFriction) {
  const double h = 0.005;
  for (double dt : {1e-3, 4e-3, 1e-2}) {
    for (double slip : {3.0, 0.3}) {
      Cloth cloth = one_free_vertex(Vec3(0.0, h + dt, 0.0));
      cloth.velocities().row(0) << slip, -2.0, 0.0;
      ClothBodyContact contact(cloth, 0.5, h);
      PlainBodies bodies;
      bodies.ground_ = ContactGround{0.0, 0.5};
      contact.collide(cloth, bodies, dt);
      const Vec3 v = cloth.velocities().row(0).transpose();
      EXPECT_NEAR(v.y(), -1.0, 1e-12) << dt;
      EXPECT_NEAR(cloth.positions()(0, 1) + dt * v.y(), h, 1e-15) << dt;
      EXPECT_NEAR(v.x(), std::max(0.0, slip - 0.5 * 1.0), 1e-12) << dt << " " << slip;
      EXPECT_EQ(v.z(), 0.0);
      // the pinned vertices took nothing
      EXPECT_EQ(cloth.velocities().bottomRows(2).norm(), 0.0);
    }
  }
}

// A vertex falling straight onto a static sphere (radius 0.5) from above its top ends the
// step exactly at the thickness from the sphere's surface
TEST(ClothBodyContact, StaticSphereStopsAVertexAtTheThickness) {
  const double h = 0.005, r = 0.5;
  const SphereDistance shape(r);
  for (double dt : {1e-3, 4e-3, 1e-2}) {
    Cloth cloth = one_free_vertex(Vec3(0.0, r + h + dt, 0.0));
    cloth.velocities().row(0) << 0.0, -2.0, 0.0;
    ClothBodyContact contact(cloth, 0.5, h);
    PlainBodies bodies;
    bodies.add(sphere(shape, r, Vec3::Zero(), 0.0), Mat3::Zero());
    contact.collide(cloth, bodies, dt);
    const Vec3 candidate = (cloth.positions().row(0) + dt * cloth.velocities().row(0)).transpose();
    EXPECT_NEAR(candidate.norm() - r, h, 1e-14) << dt;
    EXPECT_NEAR(cloth.velocities()(0, 1), -1.0, 1e-11) << dt;
  }
}

// Against a dynamic sphere (2 kg), hit off its top with slip: the vertex's velocity along the
// contact normal changes by dv_n = (h - phi) / dt, its slip relative to the sphere loses
// mu dv_n, and the sphere takes the opposite momentum (the cloth's and the sphere's momentum
// changes sum to zero) and the matching angular momentum about its centre
TEST(ClothBodyContact, DynamicSphereTakesTheOppositeMomentum) {
  const double h = 0.005, r = 0.5, mass = 2.0, mu = 0.5;
  const SphereDistance shape(r);
  const Mat3 inverse_inertia = Mat3::Identity() / (0.4 * mass * r * r);
  for (double dt : {1e-3, 4e-3, 1e-2}) {
    const Vec3 start(0.01, r + h + 0.5 * dt, -0.005);
    const Vec3 v0(1.5, -2.0, 0.5);
    Cloth cloth = one_free_vertex(start);
    cloth.velocities().row(0) = v0.transpose();
    ClothBodyContact contact(cloth, mu, h);
    PlainBodies bodies;
    bodies.add(sphere(shape, r, Vec3::Zero(), 1.0 / mass), inverse_inertia);
    bodies.bodies[0].friction = mu;  // mu = sqrt(mu mu)
    // what the contact should do, from the candidate (the sphere at rest)
    const Vec3 xc = start + dt * v0;
    const Vec3 normal = xc.normalized();
    const double phi = xc.norm() - r, dvn = (h - phi) / dt;
    ASSERT_GT(dvn, 0.0);
    const Vec3 slip = v0 - v0.dot(normal) * normal;
    ASSERT_GT(slip.norm(), mu * dvn);  // it slides

    contact.collide(cloth, bodies, dt);
    const Vec3 v = cloth.velocities().row(0).transpose();
    const double m = cloth.masses()[0];
    EXPECT_NEAR((v - v0).dot(normal), dvn, 1e-9) << dt;
    const Vec3 slip_after = v - v.dot(normal) * normal;
    EXPECT_NEAR(slip_after.norm(), slip.norm() - mu * dvn, 1e-9) << dt;
    EXPECT_LT((slip_after.normalized() - slip.normalized()).norm(), 1e-12) << dt;
    // momentum: the cloth's change plus the body's is zero
    const Vec3 cloth_change = m * (v - v0);
    EXPECT_LT((cloth_change + mass * bodies.v[0]).norm(), 1e-15 * (1.0 + cloth_change.norm())) << dt;
    EXPECT_GT(bodies.v[0].norm(), 0.0);
    EXPECT_LT((bodies.l[0] + xc.cross(cloth_change)).norm(), 1e-15) << dt;
  }
}

// A sleeping dynamic body is woken by the touch but takes no impulse in it; a kinematic one
// takes none either (the cloth is stopped all the same)
TEST(ClothBodyContact, SleepingAndKinematicBodiesTakeNothing) {
  const double h = 0.005, r = 0.5, dt = 4e-3;
  const SphereDistance shape(r);
  for (bool kinematic : {false, true}) {
    Cloth cloth = one_free_vertex(Vec3(0.0, r + h + dt, 0.0));
    cloth.velocities().row(0) << 0.0, -2.0, 0.0;
    ClothBodyContact contact(cloth, 0.5, h);
    PlainBodies bodies;
    bodies.add(sphere(shape, r, Vec3::Zero(), kinematic ? 0.0 : 0.5), Mat3::Identity());
    bodies.asleep_[0] = !kinematic;
    contact.collide(cloth, bodies, dt);
    EXPECT_NEAR(cloth.velocities()(0, 1), -1.0, 1e-11);
    EXPECT_EQ(bodies.v[0].norm(), 0.0);
    EXPECT_EQ(bodies.l[0].norm(), 0.0);
    EXPECT_FALSE(bodies.asleep(0));
  }
}

// A cloth edge passing a static box's vertical edge square to it, 2 mm outside the corner,
// its ends and the quarter points the edge is sampled at all 0.1 m or more from the box (so
// that only the body edge against the cloth edge can see it): held, its candidate comes out
// at the thickness h from the box's edge, on the outer side; driven at the corner at 1 m/s
// (its candidate 8 mm past the edge, inside), it is brought back over the edge to h on the
// side it came from, instead of passing the box's edge into the middle of its triangle.
// The cloth edge's closest point is at 0.375 of it, between two quarter samples
TEST(ClothBodyContact, ABoxEdgeHoldsAClothEdgeCrossingIt) {
  const double h = 0.005, dt = 0.01;
  const BoxDistance shape(Vec3::Constant(0.4));
  const Vec3 corner(0.2, 0.0, 0.2), out = Vec3(1.0, 0.0, 1.0).normalized(), along = Vec3(1.0, 0.0, -1.0).normalized();
  for (const double speed : {0.0, 1.0}) {
    const Vec3 closest = corner + 0.002 * out;
    ClothDesc desc;
    desc.rest.resize(3, 3);
    desc.rest.row(0) = (closest - 0.375 * 0.8 * along).transpose();
    desc.rest.row(1) = (closest + 0.625 * 0.8 * along).transpose();
    desc.rest.row(2) = (closest + 0.5 * out + Vec3(0.0, 0.3, 0.0)).transpose();
    desc.triangles.resize(1, 3);
    desc.triangles << 0, 1, 2;
    desc.pinned = {2};
    Cloth cloth(desc);
    cloth.velocities().row(0) = (-speed * out).transpose();
    cloth.velocities().row(1) = (-speed * out).transpose();
    PlainBodies bodies;
    ContactBody box;
    box.shape = &shape;
    box.bounding_radius = 0.35;
    box.kinematic = box.still = true;
    bodies.add(box, Mat3::Zero());
    ClothBodyContact contact(cloth, 0.0, h);
    contact.collide(cloth, bodies, dt);
    const Vec3 a = cloth.positions().row(0).transpose() + dt * cloth.velocities().row(0).transpose();
    const Vec3 b = cloth.positions().row(1).transpose() + dt * cloth.velocities().row(1).transpose();
    const auto [s, t] = closest_on_segments(corner - Vec3(0.0, 0.2, 0.0), corner + Vec3(0.0, 0.2, 0.0), a, b);
    const Vec3 across = a + t * (b - a) - (corner + Vec3(0.0, 0.4 * s - 0.2, 0.0));
    // (to round-off and the second-order shift of the closest point as the edge turns)
    EXPECT_NEAR(across.norm(), h, 1e-4 * h) << speed;
    EXPECT_GT(across.dot(out), 0.0) << speed;  // the outer side
    EXPECT_GT(t, 0.3) << speed;
    EXPECT_LT(t, 0.45) << speed;
  }
}

TEST(ClosestPoints, Segments) {
  // square skew segments, an end against a middle, parallel ones (a pair of closest points),
  // and a degenerate one (its point)
  auto [s, t] = closest_on_segments(Vec3(0, 0, 0), Vec3(2, 0, 0), Vec3(0.5, -1, 1), Vec3(0.5, 1, 1));
  EXPECT_NEAR(s, 0.25, 1e-15);
  EXPECT_NEAR(t, 0.5, 1e-15);
  std::tie(s, t) = closest_on_segments(Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(3, -1, 0), Vec3(3, 1, 0));
  EXPECT_EQ(s, 1.0);
  EXPECT_NEAR(t, 0.5, 1e-15);
  std::tie(s, t) = closest_on_segments(Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0.5, 1, 0), Vec3(2, 1, 0));
  EXPECT_NEAR(s, 0.5, 1e-15);  // overlapping from x = 0.5: one of the pairs 1 apart
  EXPECT_EQ(t, 0.0);
  std::tie(s, t) = closest_on_segments(Vec3(0, 0, 0), Vec3(0, 0, 0), Vec3(-1, 1, 0), Vec3(1, 1, 0));
  EXPECT_EQ(s, 0.0);
  EXPECT_NEAR(t, 0.5, 1e-15);
}

// A moving keyed body passes through the vertices the cloth let into it (ContactBody::let_in:
// a keyed obstacle the cloth gave way to, contact/cloth_obstacles.h) and those inside it at
// the step's start that a still surface holds (the ground it presses the cloth into): neither
// is pushed. One inside it that nothing else holds (a curtain it crosses), one outside it
// that the step would take inside, and one inside a still body are pushed out to the thickness
TEST(ClothBodyContact, AMovingKeyedBodyPassesThroughTheVerticesHeldInsideIt) {
  const double h = 0.005, r = 0.5, dt = 0.01;
  const SphereDistance shape(r);
  const std::vector<char> flags = {1, 0, 0};
  struct Case {
    double start;        // the vertex's height over the sphere's centre (the sphere at rest)
    double speed;        // its velocity, down (m/s)
    bool moving, let_in, on_ground, pushed;
  };
  for (const Case& c : {Case{r + 0.01, 11.0, true, false, false, true}, Case{r + 0.01, 11.0, true, true, false, false},
                        Case{r - 0.1, 0.0, true, false, false, true}, Case{r - 0.1, 0.0, true, false, true, false},
                        Case{r - 0.1, 0.0, false, false, true, true}}) {
    Cloth cloth = one_free_vertex(Vec3(0.0, c.start, 0.0));
    ClothBodyContact contact(cloth, 0.5, h);
    PlainBodies bodies;
    if (c.on_ground) {
      // the ground 1 mm above the vertex: its contact this step makes the vertex one a still
      // surface holds (a first pass, the sphere not there yet); then the step's next pass
      bodies.ground_ = ContactGround{c.start + 0.001, 0.5};
      contact.collide(cloth, bodies, dt);
      bodies.ground_.reset();
    }
    bodies.add(sphere(shape, r, Vec3::Zero(), 0.0), Mat3::Zero());
    bodies.bodies[0].still = !c.moving;  // (keyed and moving, at rest within this step's test)
    if (c.let_in) bodies.bodies[0].let_in = &flags;
    cloth.velocities().row(0) << 0.0, -c.speed, 0.0;
    contact.collide(cloth, bodies, dt);
    const Vec3 candidate = (cloth.positions().row(0) + dt * cloth.velocities().row(0)).transpose();
    if (c.pushed) {
      EXPECT_NEAR(candidate.norm() - r, h, 1e-12) << c.start << " " << c.moving << " " << c.on_ground;
    } else {
      EXPECT_EQ(cloth.velocities()(0, 1), -c.speed) << c.start << " " << c.let_in << " " << c.on_ground;
    }
  }
}
