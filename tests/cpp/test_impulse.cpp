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
