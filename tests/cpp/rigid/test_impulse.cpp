// The impulse formulas of the seed notes against hand-computed values and their defining
// properties (post-impulse relative velocity, friction cone).
#include <gtest/gtest.h>

#include "rigid/impulse.h"

#include <random>

using namespace simbake;

TEST(Impulse, KMatrixByHand) {
  // r = (1, 0, 0), I^-1 = diag(a, b, c): r*^T I^-1 r* = diag(0, c, b)
  const Mat3 K = impulse_matrix(0.5, Vec3(2.0, 3.0, 5.0).asDiagonal(), Vec3(1.0, 0.0, 0.0));
  Mat3 expected = Mat3::Zero();
  expected.diagonal() << 0.5, 0.5 + 5.0, 0.5 + 3.0;
  EXPECT_TRUE(K.isApprox(expected, 1e-15));
}

TEST(Impulse, FrictionlessByHand) {
  // a 2 kg body hit at its centre line: K n = n / M, j = -(1 + e) n.v / (1 / M) = 1.5 * 3 * 2
  const Mat3 K = impulse_matrix(0.5, Mat3::Identity(), Vec3(0.0, -1.0, 0.0));
  const Vec3 J = frictionless_impulse(K, Vec3::UnitY(), Vec3(0.3, -3.0, 0.0), 0.5);
  EXPECT_TRUE(J.isApprox(Vec3(0.0, 9.0, 0.0), 1e-14));
}

TEST(Impulse, StaticInsideConeByHand) {
  // K = Id / M with M = 2: J = -M (v + e (v.n) n) = -2 ((1, -3, 0) + 0.5 (-3) (0, 1, 0))
  const Mat3 K = 0.5 * Mat3::Identity();
  const Vec3 v(1.0, -3.0, 0.0), n = Vec3::UnitY();
  const Vec3 J = static_impulse(K, n, v, 0.5);
  EXPECT_TRUE(J.isApprox(Vec3(-2.0, 9.0, 0.0), 1e-14));
  EXPECT_TRUE(inside_friction_cone(J, n, 0.5));   // |J_T| = 2 <= 0.5 * 9
  EXPECT_FALSE(inside_friction_cone(J, n, 0.1));  // 2 > 0.9
  EXPECT_TRUE(coulomb_impulse(K, n, v, 0.5, 0.5).isApprox(J, 1e-14));
}

TEST(Impulse, SlidingOnTheConeByHand) {
  // mu = 0.1 rejects the static impulse; T = (1, 0, 0), j = 4.5 / (n.K(n - mu T)) = 9
  const Mat3 K = 0.5 * Mat3::Identity();
  const Vec3 v(1.0, -3.0, 0.0), n = Vec3::UnitY();
  const Vec3 J = coulomb_impulse(K, n, v, 0.5, 0.1);
  EXPECT_TRUE(J.isApprox(Vec3(-0.9, 9.0, 0.0), 1e-14));
  const Vec3 after = v + K * J;
  EXPECT_NEAR(after.dot(n), 1.5, 1e-14);  // -e v.n
  EXPECT_NEAR(after.x(), 0.55, 1e-14);    // still sliding, slower
}

TEST(Impulse, NoTangentialVelocityMeansNoFriction) {
  const Mat3 K = 0.5 * Mat3::Identity();
  const Vec3 J = sliding_impulse(K, Vec3::UnitY(), Vec3(0.0, -2.0, 0.0), 0.0, 0.7);
  EXPECT_TRUE(J.isApprox(Vec3(0.0, 4.0, 0.0), 1e-14));
}

TEST(Impulse, DefiningPropertiesOnRandomBodies) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  auto vec = [&] { return Vec3(u(rng), u(rng), u(rng)); };
  for (int trial = 0; trial < 200; ++trial) {
    const Mat3 A = Mat3::NullaryExpr([&] { return u(rng); });
    const Mat3 inverse_inertia = A * A.transpose() + 0.1 * Mat3::Identity();
    const Mat3 K = impulse_matrix(0.3, inverse_inertia, vec()) + impulse_matrix(0.7, inverse_inertia, vec());
    const Vec3 n = vec().normalized();
    Vec3 v = vec();
    if (v.dot(n) > 0.0) v -= 2.0 * v.dot(n) * n;  // approaching
    const double e = 0.5 * (u(rng) + 1.0), mu = 0.5 * (u(rng) + 1.0);

    // static: the relative velocity afterwards is exactly -e (v.n) n
    const Vec3 Js = static_impulse(K, n, v, e);
    EXPECT_TRUE((v + K * Js).isApprox(-e * v.dot(n) * n, 1e-9));
    // frictionless: normal component reversed and scaled by e
    const Vec3 Jf = frictionless_impulse(K, n, v, e);
    EXPECT_NEAR((v + K * Jf).dot(n), -e * v.dot(n), 1e-10);
    // coulomb: the normal condition always holds, and the impulse is in or on the cone
    const Vec3 J = coulomb_impulse(K, n, v, e, mu);
    EXPECT_NEAR((v + K * J).dot(n), -e * v.dot(n), 1e-9);
    const double jn = J.dot(n);
    EXPECT_GE(jn, 0.0);
    EXPECT_LE((J - jn * n).norm(), mu * jn * (1.0 + 1e-9) + 1e-12);
  }
}

// No impact gains energy: dE = J.v + J.K J / 2 <= 0 for the Coulomb impulse on random bodies,
// restitutions up to 1 and frictions up to 2, although the static impulse alone gains in
// some of them (e > 0 off the centre line) and the guard has to step in
TEST(Impulse, CoulombImpulseNeverGainsEnergy) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  auto vec = [&] { return Vec3(u(rng), u(rng), u(rng)); };
  int static_gains = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    const Mat3 A = Mat3::NullaryExpr([&] { return u(rng); });
    const Mat3 inverse_inertia = A * A.transpose() + 0.01 * Mat3::Identity();
    const Mat3 K = impulse_matrix(0.5, inverse_inertia, 2.0 * vec());
    const Vec3 n = vec().normalized();
    Vec3 v = vec();
    if (v.dot(n) > 0.0) v -= 2.0 * v.dot(n) * n;  // approaching
    const double e = 0.5 * (u(rng) + 1.0), mu = u(rng) + 1.0;
    const double scale = v.dot(K.ldlt().solve(v));  // 2 x the most energy an impulse can take
    if (impulse_energy_change(K, v, static_impulse(K, n, v, e)) > 1e-12 * scale) ++static_gains;
    const Vec3 J = coulomb_impulse(K, n, v, e, mu);
    EXPECT_LE(impulse_energy_change(K, v, J), 1e-12 * scale) << "trial " << trial;
    EXPECT_NEAR((v + K * J).dot(n), -e * v.dot(n), 1e-9 * (1.0 + v.norm()));  // still -e v.n
  }
  EXPECT_GT(static_gains, 0);
}

// Iterating the update on one point alone converges to the notes' inelastic Coulomb impulse
// whenever K is isotropic in the tangent plane (contact in line with the centre of mass)
TEST(Impulse, ContactUpdateConvergesToTheNotesImpulseForOnePoint) {
  const Mat3 K = 0.5 * Mat3::Identity();
  const Vec3 n = Vec3::UnitY();
  for (const Vec3& v0 : {Vec3(1.0, -3.0, 0.0), Vec3(0.2, -1.0, -0.7), Vec3(-4.0, -0.5, 2.0)}) {
    for (double mu : {0.0, 0.1, 0.5, 2.0}) {
      Vec3 total = Vec3::Zero();
      for (int k = 0; k < 50; ++k) total = contact_impulse_update(K, n, v0 + K * total, total, mu);
      EXPECT_TRUE(total.isApprox(coulomb_impulse(K, n, v0, 0.0, mu), 1e-9)) << mu;
    }
  }
}

// Fixed points for a point on the surface of real bodies (a unit cube and a 1 x 0.5 x 0.25
// brick, 1 kg, any orientation of the contact normal, any velocity): inelastic, inside the
// cone, and when on the cone the friction opposes the remaining slip. Alone, a point near an
// edge (strong rotational coupling) can converge slowly: every case must stay in the cone
// with a normal velocity below 1e-3 of the impact speed, and 98% must reach the fixed point
// to 1e-9 (in the world the other contact points of a face take most of the load).
TEST(Impulse, ContactUpdateFixedPointIsCoulomb) {
  int cases = 0, converged = 0;
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  auto vec = [&] { return Vec3(u(rng), u(rng), u(rng)); };
  int sliding = 0;
  for (const Vec3 size : {Vec3(1.0, 1.0, 1.0), Vec3(1.0, 0.5, 0.25)}) {
    const Vec3 sq = size.cwiseAbs2();
    const Vec3 inertia = Vec3(sq.y() + sq.z(), sq.x() + sq.z(), sq.x() + sq.y()) / 12.0;
    for (int trial = 0; trial < 200; ++trial) {
      // a point on the surface: a random point of the box pushed onto one face
      Vec3 r = 0.5 * size.cwiseProduct(vec());
      const int axis = trial % 3;
      r[axis] = (u(rng) < 0 ? -0.5 : 0.5) * size[axis];
      const Mat3 K = impulse_matrix(1.0, inertia.cwiseInverse().asDiagonal(), r);
      Vec3 n = vec().normalized();
      Vec3 v0 = vec();
      if (v0.dot(n) > 0.0) v0 -= 2.0 * v0.dot(n) * n;
      for (double mu : {0.2, 0.6}) {
        Vec3 total = Vec3::Zero();
        for (int k = 0; k < 500; ++k) total = contact_impulse_update(K, n, v0 + K * total, total, mu);
        const Vec3 v = v0 + K * total;
        const double jn = total.dot(n);
        const Vec3 jt = total - jn * n, slip = v - v.dot(n) * n;
        ++cases;
        EXPECT_LT(std::abs(v.dot(n)), 1e-3 * v0.norm());
        EXPECT_LE(jt.norm(), mu * jn * (1.0 + 1e-12));
        bool fixed = std::abs(v.dot(n)) < 1e-9;
        if (slip.norm() > 1e-6) {
          ++sliding;
          fixed = fixed && std::abs(jt.norm() - mu * jn) < 1e-9 &&
                  jt.normalized().dot(-slip.normalized()) > 1.0 - 1e-6;
        }
        converged += fixed;
      }
    }
  }
  EXPECT_GT(sliding, 100);
  EXPECT_GE(converged, 0.98 * cases);
}
