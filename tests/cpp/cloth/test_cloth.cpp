// Cloth physics with known answers: force = -gradient of the energy and Hessian = -Jacobian
// of the force (finite differences); a hanging strip's static stretch; energy that does not
// grow; a cylinder's bending energy; the StVK stress of a stretched membrane; strain
// limiting; rigid motion that damping leaves alone; the explicit stability limit.
#include <gtest/gtest.h>

#include "cloth/cloth.h"
#include "cloth/cloth_forces.h"
#include "test_support.h"

#include <Eigen/Eigenvalues>

#include <cmath>
#include <cstdio>
#include <random>

using namespace simbake;
using namespace simbake::cloth_detail;

namespace {

// a grid cloth with its (0, 0) corner at the origin
ClothDesc grid(int nx, int nz, double size_x, double size_z) { return test::grid_cloth(nx, nz, size_x, size_z); }

Points random_offsets(int n, double amplitude, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-amplitude, amplitude);
  Points p(n, 3);
  for (int k = 0; k < n; ++k) p.row(k) << u(rng), u(rng), u(rng);
  return p;
}

Vec3 row(const Points& x, int k) { return x.row(k).transpose(); }

double total_energy(const ForceModel& model, const Points& x) { return model.stretch_energy(x) + model.bend_energy(x); }

Eigen::VectorXd forces(const ForceModel& model, const Points& x) {
  Eigen::VectorXd f = Eigen::VectorXd::Zero(3 * x.rows());
  Assembly what;
  what.force = &f;
  model.assemble(x, what);
  return f;
}

Eigen::MatrixXd hessian(const ForceModel& model, const Points& x) {
  std::vector<int> every_vertex(x.rows());
  for (int k = 0; k < x.rows(); ++k) every_vertex[k] = k;
  const MatrixPattern pattern(model, every_vertex);
  Eigen::SparseMatrix<double> H = pattern.make_matrix();
  Assembly what;
  what.hessian_weight = 1.0;
  what.pattern = &pattern;
  what.matrix = &H;
  model.assemble(x, what);
  return Eigen::MatrixXd(H);
}

// central differences of the total energy: -gradient
Eigen::VectorXd fd_forces(const ForceModel& model, Points x, double h) {
  Eigen::VectorXd f(3 * x.rows());
  for (int k = 0; k < x.rows(); ++k) {
    for (int c = 0; c < 3; ++c) {
      const double keep = x(k, c);
      x(k, c) = keep + h;
      const double plus = total_energy(model, x);
      x(k, c) = keep - h;
      const double minus = total_energy(model, x);
      x(k, c) = keep;
      f[3 * k + c] = -(plus - minus) / (2.0 * h);
    }
  }
  return f;
}

// central differences of the forces: -Hessian
Eigen::MatrixXd fd_hessian(const ForceModel& model, Points x, double h) {
  Eigen::MatrixXd H(3 * x.rows(), 3 * x.rows());
  for (int k = 0; k < x.rows(); ++k) {
    for (int c = 0; c < 3; ++c) {
      const double keep = x(k, c);
      x(k, c) = keep + h;
      const Eigen::VectorXd plus = forces(model, x);
      x(k, c) = keep - h;
      const Eigen::VectorXd minus = forces(model, x);
      x(k, c) = keep;
      H.col(3 * k + c) = -(plus - minus) / (2.0 * h);
    }
  }
  return H;
}

// One world-order substep without collisions
void substep(Cloth& cloth, double dt, const Vec3& gravity) {
  cloth.update_velocities(dt, gravity);
  cloth.limit_strain(dt);
  cloth.update_positions(dt);
}

double edge_length(const Points& x, int a, int b) { return (row(x, a) - row(x, b)).norm(); }

}  // namespace

// ---------------------------------------------------------------------------------------------
// (3) gradients and Hessians against finite differences

// The forces of every model are the negative gradient of the energy at random deformed
// states (curved rest mesh, so rest angles are not zero; mixed tension and compression, so
// subgrid springs and principal strains of both signs occur). Central differences with
// step 1e-6 m have truncation error ~1e-12 and rounding error ~1e-16 W / h ~ 1e-10 W,
// well below the 1e-6 relative tolerance asked.
TEST(ClothForces, ForcesAreTheNegativeEnergyGradient) {
  ClothDesc d = grid(5, 4, 0.4, 0.3);
  d.rest += random_offsets(d.rest.rows(), 0.02, 1);  // a curved, irregular rest shape
  struct Case {
    InPlaneModel model;
    CompressionMode compression;
    const char* name;
  };
  for (const Case& c : {Case{InPlaneModel::kSprings, CompressionMode::kSubgrid, "springs subgrid"},
                        Case{InPlaneModel::kSprings, CompressionMode::kNone, "springs none"},
                        Case{InPlaneModel::kMembrane, CompressionMode::kSubgrid, "membrane subgrid"},
                        Case{InPlaneModel::kMembrane, CompressionMode::kNone, "membrane none"}}) {
    ClothMaterial m;
    m.model = c.model;
    m.compression = c.compression;
    m.subgrid_scale = 0.1;
    m.stretch_stiffness = 100.0;
    m.bend_stiffness = 0.05;
    m.poisson_ratio = 0.3;
    const ForceModel model(d.rest, d.triangles, m);
    for (unsigned seed = 2; seed < 5; ++seed) {
      Points x = 1.05 * d.rest + random_offsets(d.rest.rows(), 0.03, seed);
      const Eigen::VectorXd f = forces(model, x), f_fd = fd_forces(model, x, 1e-6);
      EXPECT_LT((f - f_fd).norm(), 1e-6 * f.norm()) << c.name << " seed " << seed;
    }
  }
}

// Bending alone, and the dihedral angle's closed-form gradient, at random hinges
TEST(ClothForces, DihedralAngleGradientMatchesFiniteDifferences) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-0.3, 0.3);
  for (int trial = 0; trial < 20; ++trial) {
    Vec3 p[4] = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0.4, 0.8, 0), Vec3(0.6, -0.9, 0)};
    for (Vec3& q : p) q += Vec3(u(rng), u(rng), 3.0 * u(rng));
    const Vec12 g = dihedral_angle_gradient(p[0], p[1], p[2], p[3]);
    Vec12 g_fd;
    const double h = 1e-6;
    for (int k = 0; k < 12; ++k) {
      Vec3 plus[4] = {p[0], p[1], p[2], p[3]}, minus[4] = {p[0], p[1], p[2], p[3]};
      plus[k / 3][k % 3] += h;
      minus[k / 3][k % 3] -= h;
      g_fd[k] = (dihedral_angle(plus[0], plus[1], plus[2], plus[3]) -
                 dihedral_angle(minus[0], minus[1], minus[2], minus[3])) / (2.0 * h);
    }
    EXPECT_LT((g - g_fd).norm(), 1e-7 * g.norm()) << trial;
  }
  // a right-angle fold: x3 lifted straight up out of the plane of (x0, x1, x2)
  EXPECT_NEAR(std::abs(dihedral_angle(Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0.5, 1, 0), Vec3(0.5, 0, 1))), M_PI / 2, 1e-12);
  EXPECT_NEAR(dihedral_angle(Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0.5, 1, 0), Vec3(0.5, -1, 0)), 0.0, 1e-15);
}

// In tension no clamping applies (springs keep their transverse term; the membrane's
// Hessian is already positive semi-definite, so the projection leaves it), and the
// assembled Hessian is exactly minus the force Jacobian: central differences of the
// forces, step 1e-6, agree to ~1e-9 relative (tolerance 1e-6 of the largest entry).
TEST(ClothForces, HessianMatchesForceJacobianInTension) {
  const ClothDesc d = grid(4, 4, 0.3, 0.3);
  for (InPlaneModel model_kind : {InPlaneModel::kSprings, InPlaneModel::kMembrane}) {
    ClothMaterial m;
    m.model = model_kind;
    m.stretch_stiffness = 100.0;
    m.bend_stiffness = 0.0;  // bending uses the Gauss-Newton part, not the exact Hessian
    const ForceModel model(d.rest, d.triangles, m);
    // stretched 10% both ways, a little out of plane: every edge and principal strain in tension
    Points x = d.rest;
    x.col(0) *= 1.1;
    x.col(2) *= 1.1;
    x += random_offsets(x.rows(), 0.004, 11);
    for (const Edge& e : model.edges()) ASSERT_GT(edge_length(x, e.i, e.j), e.rest);
    const Eigen::MatrixXd H = hessian(model, x), H_fd = fd_hessian(model, x, 1e-6);
    EXPECT_LT((H - H_fd).cwiseAbs().maxCoeff(), 1e-6 * H.cwiseAbs().maxCoeff()) << int(model_kind);
    EXPECT_LT((H - H.transpose()).cwiseAbs().maxCoeff(), 1e-9 * H.cwiseAbs().maxCoeff());
  }
}

// Under compression the clamped Hessian stays positive semi-definite (what makes the
// implicit system solvable by conjugate gradients)
TEST(ClothForces, ClampedHessianIsPositiveSemiDefinite) {
  ClothDesc d = grid(5, 5, 0.4, 0.4);
  for (InPlaneModel model_kind : {InPlaneModel::kSprings, InPlaneModel::kMembrane}) {
    ClothMaterial m;
    m.model = model_kind;
    m.compression = CompressionMode::kNone;
    m.stretch_stiffness = 100.0;
    m.bend_stiffness = 0.01;
    const ForceModel model(d.rest, d.triangles, m);
    Points x = 0.8 * d.rest + random_offsets(d.rest.rows(), 0.05, 3);
    const Eigen::MatrixXd H = hessian(model, x);
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(H);
    EXPECT_GT(eigen.eigenvalues().minCoeff(), -1e-9 * eigen.eigenvalues().maxCoeff()) << int(model_kind);
  }
}

// ---------------------------------------------------------------------------------------------
// (7) membrane: StVK stress of a uniformly stretched square

// A homogeneous deformation is represented exactly by linear triangles, so the interior
// vertices carry no net force and the forces on the right edge add up to -P11 H (P = F S
// the first Piola-Kirchhoff stress, H the rest height), on the top edge to -P22 W, to
// rounding (tolerance 1e-9 relative). Uniaxial strain (sides held): P11 = s (lambda + 2 mu)
// G11, P22 = lambda G11. Uniaxial stress (sides free to narrow by G22 = -nu G11): P11 =
// s Y G11, P22 = 0 -- this one checks the plane-stress Lame parameters. The whole picture
// is also turned by an arbitrary rotation, which must turn the forces with it.
TEST(ClothMembrane, UniformStretchGivesStVKStress) {
  const double W = 1.0, H = 0.8, Y = 1000.0, nu = 0.3, s = 1.2;
  const ClothDesc d = grid(7, 6, W, H);  // x along W, z along H
  const Lame lame = lame_parameters(Y, nu);
  const double G11 = 0.5 * (s * s - 1.0);
  const Mat3 R = Eigen::AngleAxisd(0.7, Vec3(1, 2, 3).normalized()).toRotationMatrix();
  struct Case {
    double t;  // stretch across
    double p11, p22;
    CompressionMode compression;
  };
  const double t_free = std::sqrt(1.0 - 2.0 * nu * G11);  // G22 = -nu G11
  for (const Case& c : {Case{1.0, s * (lame.lambda + 2.0 * lame.mu) * G11, lame.lambda * G11, CompressionMode::kSubgrid},
                        Case{t_free, s * Y * G11, 0.0, CompressionMode::kNone}}) {
    ClothMaterial m;
    m.model = InPlaneModel::kMembrane;
    m.stretch_stiffness = Y;
    m.poisson_ratio = nu;
    m.bend_stiffness = 0.0;
    m.compression = c.compression;
    const ForceModel model(d.rest, d.triangles, m);
    Points x = d.rest;
    x.col(0) *= s;
    x.col(2) *= c.t;
    x = (x * R.transpose()).eval();
    const Eigen::VectorXd f = forces(model, x);
    Vec3 right = Vec3::Zero(), top = Vec3::Zero();
    double interior = 0.0;
    for (int k = 0; k < x.rows(); ++k) {
      const Vec3 fk = R.transpose() * Vec3(f.segment<3>(3 * k));  // back in the sheet's frame
      const bool on_right = d.rest(k, 0) > W - 1e-12, on_top = d.rest(k, 2) > H - 1e-12;
      const bool on_left = d.rest(k, 0) < 1e-12, on_bottom = d.rest(k, 2) < 1e-12;
      if (on_right) right += fk;
      if (on_top) top += fk;
      if (!on_right && !on_left && !on_top && !on_bottom) interior = std::max(interior, fk.norm());
    }
    // the right edge's corner vertices also belong to the top/bottom edges: their share of
    // the z forces cancels between the corners, and their x forces are all P11 (cell-wise)
    EXPECT_NEAR(-right.x(), c.p11 * H, 1e-9 * c.p11 * H) << c.t;
    EXPECT_NEAR(-top.z(), c.p22 * W, 1e-9 * c.p11 * W) << c.t;
    EXPECT_LT(interior, 1e-9 * c.p11 * H);
  }
}

// Springs stand for the same sheet at any resolution: a grid stretched uniformly along x by
// a small strain e (its width held) stores 1/2 Y e^2 per unit area (the calibration in
// cloth_forces.cpp), whatever its spacing, to O(e) (the springs' strain is |A| - 1, not Green's);
// tolerance 1% at e = 1e-3. And a grid's bending energy on a cylinder is resolution-free
// (next test), so both halves of a spring cloth are.
TEST(ClothSprings, StiffnessIsTheSheetsAtAnyResolution) {
  const double Y = 2000.0, e = 1e-3, W = 1.0, H = 1.0;  // square cells (the calibration is for them)
  for (int n : {5, 17, 65}) {
    const ClothDesc d = grid(n, n, W, H);
    ClothMaterial m;
    m.stretch_stiffness = Y;
    m.bend_stiffness = 0.0;
    const ForceModel model(d.rest, d.triangles, m);
    Points x = d.rest;
    x.col(0) *= 1.0 + e;
    const double density = model.stretch_energy(x) / (W * H);
    std::printf("  springs, %d x %d grid: energy density / (1/2 Y e^2) = %.5f\n", n, n, density / (0.5 * Y * e * e));
    EXPECT_NEAR(density, 0.5 * Y * e * e, 0.01 * 0.5 * Y * e * e) << n;
  }
}

// ---------------------------------------------------------------------------------------------
// (4) bending: a cylinder's energy converges to B / (2 R^2) x area

// A flat rest patch bent onto a cylinder of radius R. Only bending counts (stretch
// stiffness 0). Grid with the axis along a grid direction: every axial hinge turns by h / R
// exactly, the others stay flat, so the energy is B / (2 R^2) area (n - 1) / n: the error is
// the one missing hinge column at the boundary, 1/n. An equilateral mesh turned 0.3 rad off
// the axis (the hinge angles now mix the three edge directions) converges the same way.
TEST(ClothBending, CylinderEnergyConvergesToContinuum) {
  const double R = 0.5, B = 2e-3;
  const double arc = 0.5 * M_PI * R, length = 0.6;  // a quarter of the cylinder
  auto wrap = [R](double u, double v) { return Vec3(R * std::sin(u / R), R * (1.0 - std::cos(u / R)), v); };
  ClothMaterial m;
  m.stretch_stiffness = 0.0;
  m.bend_stiffness = B;
  std::printf("  cylinder bending energy / (B / (2 R^2) x area):\n  %8s %12s %12s\n", "n", "grid", "equilateral");
  double previous_grid = 0.0, previous_tri = 0.0;  // (error 1 before the first resolution)
  for (int n : {4, 8, 16, 32, 64}) {
    // (a) grid: n cells around, proportionally many along
    const int nz = std::max(2, int(std::lround(n * length / arc)));
    ClothDesc d = grid(n + 1, nz + 1, arc, length);
    d.material = m;
    Cloth flat_grid(d);
    for (int k = 0; k < d.rest.rows(); ++k) flat_grid.positions().row(k) = wrap(d.rest(k, 0), d.rest(k, 2)).transpose();
    const double grid_ratio = flat_grid.elastic_energy() / (B / (2 * R * R) * arc * length);
    // (b) equilateral triangles of side ~ arc / n in a rectangle turned by 0.3 rad
    const double side = arc / n, rowh = side * std::sqrt(3.0) / 2.0, angle = 0.3;
    const int cols = int(std::ceil(1.2 * std::hypot(arc, length) / side)) + 2;
    const int rows = int(std::ceil(1.2 * std::hypot(arc, length) / rowh)) + 2;
    // lattice points (c + r/2 mod 1, r), turned, centred on the patch; keep the triangles
    // whose three corners fall inside [0, arc] x [0, length]
    std::vector<Vec3> uv;
    for (int r = 0; r < rows; ++r) {
      for (int c = 0; c < cols; ++c) {
        const double a = (c + 0.5 * (r % 2) - 0.5 * cols) * side, b = (r - 0.5 * rows) * rowh;
        uv.emplace_back(0.5 * arc + std::cos(angle) * a - std::sin(angle) * b,
                        0.5 * length + std::sin(angle) * a + std::cos(angle) * b, 0.0);
      }
    }
    auto inside = [&](int k) { return uv[k].x() >= 0 && uv[k].x() <= arc && uv[k].y() >= 0 && uv[k].y() <= length; };
    std::vector<int> index(uv.size(), -1);
    std::vector<Eigen::Vector3i> tris;
    for (int r = 0; r + 1 < rows; ++r) {
      for (int c = 0; c + 1 < cols; ++c) {
        const int a = r * cols + c, b = a + 1, up = (r + 1) * cols + c, up1 = up + 1;
        // rows alternate their half-cell offset: even rows point the triangles one way
        const Eigen::Vector3i t1 = r % 2 == 0 ? Eigen::Vector3i(a, b, up) : Eigen::Vector3i(a, b, up1);
        const Eigen::Vector3i t2 = r % 2 == 0 ? Eigen::Vector3i(b, up1, up) : Eigen::Vector3i(a, up1, up);
        for (const Eigen::Vector3i& t : {t1, t2}) {
          if (inside(t[0]) && inside(t[1]) && inside(t[2])) tris.push_back(t);
        }
      }
    }
    ClothDesc e;
    std::vector<int> used;
    for (const auto& t : tris) {
      for (int k = 0; k < 3; ++k) {
        if (index[t[k]] < 0) {
          index[t[k]] = int(used.size());
          used.push_back(t[k]);
        }
      }
    }
    e.rest.resize(used.size(), 3);
    for (size_t k = 0; k < used.size(); ++k) e.rest.row(k) << uv[used[k]].x(), 0.0, uv[used[k]].y();
    e.triangles.resize(tris.size(), 3);
    double area = 0.0;
    for (size_t t = 0; t < tris.size(); ++t) {
      e.triangles.row(t) << index[tris[t][0]], index[tris[t][1]], index[tris[t][2]];
      area += 0.5 * std::sqrt(3.0) / 2.0 * side * side;
    }
    e.material = m;
    Cloth lattice(e);
    for (int k = 0; k < e.rest.rows(); ++k) lattice.positions().row(k) = wrap(e.rest(k, 0), e.rest(k, 2)).transpose();
    const double tri_ratio = lattice.elastic_energy() / (B / (2 * R * R) * area);
    std::printf("  %8d %12.5f %12.5f\n", n, grid_ratio, tri_ratio);
    // the grid's error is exactly the missing boundary hinge column
    EXPECT_NEAR(grid_ratio, double(n - 1) / n, 1e-3) << n;
    // both converge: the error shrinks with refinement, to under 5% at n = 64
    EXPECT_LT(std::abs(1.0 - grid_ratio), std::abs(1.0 - previous_grid) + 1e-12);
    EXPECT_LT(std::abs(1.0 - tri_ratio), std::abs(1.0 - previous_tri) + 1e-12);
    previous_grid = grid_ratio;
    previous_tri = tri_ratio;
  }
  EXPECT_LT(std::abs(1.0 - previous_grid), 0.05);
  EXPECT_LT(std::abs(1.0 - previous_tri), 0.05);
}

// The grid version with the constant 1/2 is exact for the interior; and a curved rest
// mesh (rest angle theta0) is at rest in its own shape
TEST(ClothBending, CurvedRestMeshKeepsItsShape) {
  ClothDesc d = grid(9, 5, 0.8, 0.4);
  for (int k = 0; k < d.rest.rows(); ++k) d.rest(k, 1) = 0.3 * std::sin(3.0 * d.rest(k, 0));
  d.material.bend_stiffness = 1e-2;
  Cloth cloth(d);
  EXPECT_LT(cloth.elastic_energy(), 1e-20);
  for (int s = 0; s < 48; ++s) substep(cloth, 1.0 / 240.0, Vec3::Zero());
  EXPECT_LT((cloth.positions() - d.rest).cwiseAbs().maxCoeff(), 1e-12);
}

// ---------------------------------------------------------------------------------------------
// (1) a hanging strip's static stretch

// A strip one cell wide (two columns of vertices, rungs and one diagonal per cell) pinned at
// its top two vertices. Statics per horizontal cut (three members: two sides and a diagonal)
// give each side exactly the weight of its own column below the cut and the diagonal (and
// the rungs) nothing, to first order in the strain: each side edge's strain is (weight of its
// column below) / E, and the total stretch is the sum over edges of that strain times h.
// A side edge has one triangle (area width h / 2), so for a sheet of stiffness Y its spring
// has E = 12/5 Y (width h / 6) / h = 0.4 Y width (cloth_forces.cpp): Y = 25 E here.
// The two columns carry slightly different weights (the triangulation lumps one more third
// of a triangle on one side), so the strip leans a little and the diagonals pick up load:
// a relative error of order the strain itself (measured: -0.57 x the top strain, halving
// when E doubles). Tolerance: the top strain. Damped to rest (Rayleigh damping 0.05 s,
// 3 s), for both integrators; and the error falls as the strain does (E x 4).
TEST(ClothHanging, StripReachesTheAnalyticStaticStretch) {
  const int rows = 10;
  const double h = 0.1, width = 0.1, density = 0.1, g = 9.81;
  struct Case {
    ClothIntegrator integrator;
    double E;
  };
  double error_soft = 0.0;
  for (const Case& c : {Case{ClothIntegrator::kExplicit, 20.0}, Case{ClothIntegrator::kImplicit, 20.0},
                        Case{ClothIntegrator::kImplicit, 80.0}}) {
    ClothDesc d;
    d.rest.resize(2 * (rows + 1), 3);
    for (int r = 0; r <= rows; ++r) {
      d.rest.row(2 * r) << 0.0, -h * r, 0.0;
      d.rest.row(2 * r + 1) << width, -h * r, 0.0;
    }
    d.triangles.resize(2 * rows, 3);
    for (int r = 0; r < rows; ++r) {
      const int l0 = 2 * r, r0 = 2 * r + 1, l1 = 2 * r + 2, r1 = 2 * r + 3;
      d.triangles.row(2 * r) << l0, r0, r1;
      d.triangles.row(2 * r + 1) << l0, r1, l1;
    }
    d.area_density = density;
    d.pinned = {0, 1};
    d.integrator = c.integrator;
    d.material.stretch_stiffness = c.E / (0.4 * width);
    d.material.bend_stiffness = 0.0;
    d.material.strain_limit = 0.0;
    d.material.damping = 0.05;
    Cloth cloth(d);
    // the analytic stretch: each side edge carries the weight of its column below it
    double expected = 0.0, top_strain = 0.0;
    for (int column = 0; column < 2; ++column) {
      for (int r = 0; r < rows; ++r) {
        double below = 0.0;
        for (int q = r + 1; q <= rows; ++q) below += cloth.masses()[2 * q + column];
        expected += g * below / c.E * h;
        top_strain = std::max(top_strain, g * below / c.E);
      }
    }
    const bool implicit = c.integrator == ClothIntegrator::kImplicit;
    const double dt = implicit ? 1.0 / 240.0 : cloth.stable_explicit_step();
    const int steps = int(std::ceil(3.0 / dt));
    for (int s = 0; s < steps; ++s) substep(cloth, dt, Vec3(0.0, -g, 0.0));
    double stretch = 0.0;
    for (int column = 0; column < 2; ++column) {
      for (int r = 0; r < rows; ++r) stretch += edge_length(cloth.positions(), 2 * r + column, 2 * r + 2 + column) - h;
    }
    const double error = stretch / expected - 1.0;
    std::printf("  hanging strip (%s, E %g N, dt %.3g s, %d steps): stretch %.6e m, analytic %.6e m, error %+.3f%% "
                "(top strain %.3f%%), kinetic energy %.1e J\n",
                implicit ? "implicit" : "explicit", c.E, dt, steps, stretch, expected, 100.0 * error, 100.0 * top_strain,
                cloth.kinetic_energy());
    EXPECT_LT(std::abs(error), top_strain);
    // at rest: what motion is left is a slow sideways sway (which stiffness-proportional
    // damping hardly touches), tiny next to the work gravity did
    EXPECT_LT(cloth.kinetic_energy(), 1e-5 * cloth.masses().sum() * g * expected);
    if (c.E == 20.0 && implicit) error_soft = error;
    if (c.E == 80.0) {
      EXPECT_LT(std::abs(error), 0.4 * std::abs(error_soft));
    }
  }
}

// ---------------------------------------------------------------------------------------------
// (2) energy of an undamped cloth does not grow

// Released at rest from a stretched (8% one way) and bent (a bump) state, no gravity, no
// damping, no strain limiting. Backward Euler only dissipates: the total energy never exceeds
// its start (tolerance 1e-6 relative, the CG solve's residual). Symplectic Euler (at half the
// stable step) conserves a nearby "shadow" energy instead; its natural estimate pairs the
// velocities before and after each step at x_n, W(x_n) + 1/2 v_(n-1/2) M v_(n+1/2) (exact
// for a linear system), and stays within 3% (the plain estimate swings by ~dt omega).
TEST(ClothEnergy, UndampedEnergyDoesNotGrow) {
  for (InPlaneModel model : {InPlaneModel::kSprings, InPlaneModel::kMembrane}) {
    for (ClothIntegrator integrator : {ClothIntegrator::kImplicit, ClothIntegrator::kExplicit}) {
      ClothDesc d = grid(10, 10, 0.5, 0.5);
      d.integrator = integrator;
      d.material.model = model;
      d.material.stretch_stiffness = model == InPlaneModel::kSprings ? 20.0 : 200.0;
      d.material.bend_stiffness = 1e-3;
      d.material.damping = 0.0;
      d.material.strain_limit = 0.0;
      d.material.compression = CompressionMode::kNone;
      Cloth cloth(d);
      for (int k = 0; k < d.rest.rows(); ++k) {
        const double x = d.rest(k, 0), z = d.rest(k, 2);
        cloth.positions()(k, 0) = 1.08 * x;
        cloth.positions()(k, 1) = 0.05 * std::sin(M_PI * x / 0.5) * std::sin(M_PI * z / 0.5);
      }
      const bool implicit = integrator == ClothIntegrator::kImplicit;
      const double e0 = cloth.elastic_energy();
      const double dt = implicit ? 1.0 / 240.0 : 0.5 * cloth.stable_explicit_step();
      const int steps = int(std::ceil(2.0 / dt));
      double highest = e0, lowest = e0, energy = e0;
      for (int s = 0; s < steps; ++s) {
        const Points before = cloth.velocities();
        const double elastic = cloth.elastic_energy();
        cloth.update_velocities(dt, Vec3::Zero());
        double kinetic = 0.0;
        for (int k = 0; k < cloth.vertex_count(); ++k) {
          kinetic += 0.5 * cloth.masses()[k] * before.row(k).dot(cloth.velocities().row(k));
        }
        cloth.limit_strain(dt);
        cloth.update_positions(dt);
        energy = implicit ? cloth.elastic_energy() + cloth.kinetic_energy() : elastic + kinetic;
        highest = std::max(highest, energy);
        lowest = std::min(lowest, energy);
      }
      std::printf("  energy, %s %s (dt %.3g s, %d steps): start %.5e J, end %+.3f%%, highest %+.4f%%, lowest %+.3f%%\n",
                  model == InPlaneModel::kSprings ? "springs " : "membrane", implicit ? "implicit" : "explicit", dt,
                  steps, e0, 100.0 * (energy / e0 - 1.0), 100.0 * (highest / e0 - 1.0), 100.0 * (lowest / e0 - 1.0));
      if (implicit) {
        EXPECT_LE(highest, e0 * (1.0 + 1e-6));
      } else {
        EXPECT_LT(highest, e0 * 1.03);
        EXPECT_GT(lowest, e0 * 0.97);
      }
    }
  }
}

// ---------------------------------------------------------------------------------------------
// (6) damping leaves rigid motion alone

// The damping force of a rigid velocity field is zero even in a stretched, bent state (it
// acts on strain rates only); it is not zero for a deforming one.
TEST(ClothDamping, DampingForceOfRigidMotionIsZero) {
  ClothDesc d = grid(6, 6, 0.5, 0.5);
  d.rest += random_offsets(d.rest.rows(), 0.01, 5);
  for (InPlaneModel model_kind : {InPlaneModel::kSprings, InPlaneModel::kMembrane}) {
    ClothMaterial m;
    m.model = model_kind;
    m.stretch_stiffness = 100.0;
    m.bend_stiffness = 1e-2;
    const ForceModel model(d.rest, d.triangles, m);
    const Points x = 1.1 * d.rest + random_offsets(d.rest.rows(), 0.03, 6);
    const Vec3 v0(0.3, -0.2, 0.5), w(1.0, -2.0, 0.7), centre(0.2, 0.1, 0.3);
    Points v(x.rows(), 3);
    for (int k = 0; k < x.rows(); ++k) v.row(k) = (v0 + w.cross(row(x, k) - centre)).transpose();
    auto damping_force = [&](const Points& vel) {
      Eigen::VectorXd f = Eigen::VectorXd::Zero(3 * x.rows());
      Assembly what;
      what.velocity = &vel;
      what.damping = 0.1;
      what.force = &f;
      model.assemble(x, what);
      return Eigen::VectorXd(f - forces(model, x));
    };
    const Eigen::VectorXd elastic = forces(model, x);
    EXPECT_LT(damping_force(v).norm(), 1e-12 * elastic.norm()) << int(model_kind);
    const Points deforming = v + random_offsets(x.rows(), 0.5, 8);
    EXPECT_GT(damping_force(deforming).norm(), 1e-3 * elastic.norm()) << int(model_kind);
  }
}

// A cloth translating and spinning freely with strong damping keeps its kinetic energy as
// well as the same cloth without damping does. Backward Euler itself slows a rotation at rate
// omega in an m-step: the kinetic energy falls by about exp(-2 omega^2 dt t), ~3% here for
// the spin part, the same with or without damping; damping may take no more than 1e-3 of
// the energy beyond that, and may not add any. (Explicit: damping small enough to keep the
// step reasonable.)
TEST(ClothDamping, RigidMotionIsNotDamped) {
  for (ClothIntegrator integrator : {ClothIntegrator::kImplicit, ClothIntegrator::kExplicit}) {
    double kinetic[2], start = 0.0;
    for (int run = 0; run < 2; ++run) {
      ClothDesc d = grid(8, 8, 0.5, 0.5);
      d.integrator = integrator;
      d.material.stretch_stiffness = 200.0;
      d.material.damping = run == 0 ? 0.0 : (integrator == ClothIntegrator::kImplicit ? 0.2 : 1e-3);
      d.material.strain_limit = 0.0;
      Cloth cloth(d);
      const Vec3 v0(0.5, 0.2, -0.3), w(0.3, 2.0, -0.4), centre = d.rest.colwise().mean().transpose();
      for (int k = 0; k < d.rest.rows(); ++k) cloth.velocities().row(k) = (v0 + w.cross(row(d.rest, k) - centre)).transpose();
      start = cloth.kinetic_energy();
      const double dt = integrator == ClothIntegrator::kImplicit ? 1.0 / 240.0 : cloth.stable_explicit_step();
      const int steps = int(std::ceil((integrator == ClothIntegrator::kImplicit ? 1.0 : 0.25) / dt));
      for (int s = 0; s < steps; ++s) substep(cloth, dt, Vec3::Zero());
      kinetic[run] = cloth.kinetic_energy();
    }
    std::printf("  rigid motion %s: kinetic energy kept %.6f (no damping) and %.6f (damped)\n",
                integrator == ClothIntegrator::kImplicit ? "implicit" : "explicit", kinetic[0] / start, kinetic[1] / start);
    EXPECT_GT(kinetic[1] / start, kinetic[0] / start - 1e-3);
    EXPECT_GT(kinetic[1] / start, 0.97);
    EXPECT_LT(kinetic[1] / start, 1.0);  // and damping never adds energy (nor does the solve)
  }
}

// ---------------------------------------------------------------------------------------------
// (5) strain limiting

// A square of very soft springs (E = 1 N: its own weight alone would stretch it by ~100%)
// pinned at two corners, falling under gravity: the impulses keep every edge within the 10%
// limit at every step (tolerance 1e-3; the limiter stops when every edge is within 1e-6 of
// its bound, the global pass taking over where Gauss-Seidel sweeps converge too slowly), the
// limit is reached, and the pinned corners never move.
TEST(ClothStrainLimit, SoftClothNeverStretchesBeyondTheLimit) {
  for (ClothIntegrator integrator : {ClothIntegrator::kImplicit, ClothIntegrator::kExplicit}) {
    const int n = 12;
    ClothDesc d = grid(n, n, 1.0, 1.0);
    d.area_density = 0.2;
    d.pinned = {0, n - 1};
    d.integrator = integrator;
    d.material.stretch_stiffness = 1.0;
    d.material.damping = 0.001;
    Cloth cloth(d);
    const double dt = integrator == ClothIntegrator::kImplicit ? 1.0 / 240.0 : std::min(1.0 / 240.0, cloth.stable_explicit_step());
    double largest = 0.0;
    for (int s = 0; s < int(1.5 / dt); ++s) {
      substep(cloth, dt, Vec3(0.0, -9.81, 0.0));
      largest = std::max(largest, cloth.max_strain());
      ASSERT_LT(cloth.max_strain(), 0.1 + 1e-3) << s;
    }
    std::printf("  strain limiting (%s): largest edge strain over 1.5 s %.6f\n",
                integrator == ClothIntegrator::kImplicit ? "implicit" : "explicit", largest);
    EXPECT_GT(largest, 0.099);  // the limit is what holds it
    EXPECT_EQ(row(cloth.positions(), 0), row(d.rest, 0));
    EXPECT_EQ(row(cloth.positions(), n - 1), row(d.rest, n - 1));
    EXPECT_EQ(row(cloth.velocities(), 0), Vec3::Zero());
  }
}

// A landing far beyond the limit, as a corner of the 257 x 257 drape slamming into the
// ground makes it (friction stops a vertex while its neighbours still move at 6 m/s: 580%
// strain): a sheet with a third of its vertices stopped and the rest moving together at
// ~5 m/s with noise (strains of 5-20, one step of 1/120 s over 8.7 mm edges). Whatever it
// cannot finish, the limiter never leaves the worst edge further past its bound than it found
// it, and its impulses (internal, inelastic) never add kinetic energy. Before the global
// pass's line search, 15 of 30 such sheets ended worse (one at 43 m/s from 12, strain 12 ->
// 54). Moderate distortions (0.5 m/s) still end at the limit.
TEST(ClothStrainLimit, GlobalPassNeverLeavesTheEdgesFurtherPastTheirBounds) {
  const double dt = 1.0 / 120.0;
  for (const double speed : {0.5, 5.0}) {
    for (int trial = 0; trial < 20; ++trial) {
      Cloth cloth(grid(24, 24, 0.2, 0.2));
      std::mt19937 rng(trial);
      std::normal_distribution<double> normal(0.0, 1.0);
      std::uniform_real_distribution<double> uniform(0.0, 1.0);
      const Vec3 common = speed * Vec3(normal(rng), normal(rng), normal(rng));
      for (int k = 0; k < cloth.vertex_count(); ++k) {
        const Vec3 v = (uniform(rng) < 0.3 ? Vec3::Zero() : common) + 0.3 * speed * Vec3(normal(rng), normal(rng), normal(rng));
        cloth.velocities().row(k) = v.transpose();
      }
      const double strain = cloth.candidate_strain(dt), energy = cloth.kinetic_energy();
      const double fastest = cloth.velocities().rowwise().norm().maxCoeff();
      cloth.limit_strain(dt);
      SCOPED_TRACE(::testing::Message() << "speed " << speed << " trial " << trial);
      EXPECT_LE(cloth.candidate_strain(dt), strain);
      EXPECT_LE(cloth.kinetic_energy(), energy);
      EXPECT_LE(cloth.velocities().rowwise().norm().maxCoeff(), 1.1 * fastest);
      if (speed == 0.5) EXPECT_LT(cloth.candidate_strain(dt), 0.1 + 1e-5);
    }
  }
}

// Holding vertices still (World does it with self-collision's impact zones), the limiter
// reports the pushes the held ones took from their edges: with them, linear momentum balances
// exactly, in the sweeps and in the global pass (the sheets of the test above, a third held)
TEST(ClothStrainLimit, HeldVerticesReportThePushesTheyAbsorb) {
  const double dt = 1.0 / 120.0;
  for (const double speed : {0.5, 5.0}) {
    for (int trial = 0; trial < 10; ++trial) {
      Cloth cloth(grid(24, 24, 0.2, 0.2));
      std::mt19937 rng(trial);
      std::normal_distribution<double> normal(0.0, 1.0);
      std::uniform_real_distribution<double> uniform(0.0, 1.0);
      std::vector<char> held(cloth.vertex_count(), 0);
      for (int k = 0; k < cloth.vertex_count(); ++k) {
        held[k] = uniform(rng) < 0.3;
        cloth.velocities().row(k) = (speed * Vec3(normal(rng), normal(rng), normal(rng))).transpose();
      }
      const Points before = cloth.velocities();
      const Points pushed = cloth.limit_strain_holding(dt, held);
      SCOPED_TRACE(::testing::Message() << "speed " << speed << " trial " << trial);
      Vec3 momentum = Vec3::Zero();
      double scale = 0.0;
      for (int k = 0; k < cloth.vertex_count(); ++k) {
        const Vec3 gained = cloth.masses()[k] * (cloth.velocities().row(k) - before.row(k)).transpose();
        if (held[k]) {
          EXPECT_EQ(gained.norm(), 0.0);
        } else {
          EXPECT_EQ(pushed.row(k).norm(), 0.0);
        }
        momentum += gained + pushed.row(k).transpose();
        scale += gained.norm() + pushed.row(k).norm();
      }
      EXPECT_GT(pushed.norm(), 0.0);
      EXPECT_LT(momentum.norm(), 1e-12 * scale);
    }
  }
}

// kEnforce: a cloth pushed together never has an edge shorter than its rest length at the
// end of a step (beyond the -0.001 threshold); kSubgrid lets it compress
TEST(ClothStrainLimit, EnforcedBucklingKeepsEdgesFromShortening) {
  for (CompressionMode mode : {CompressionMode::kEnforce, CompressionMode::kSubgrid}) {
    ClothDesc d = grid(8, 8, 0.5, 0.5);
    d.material.compression = mode;
    d.material.stretch_stiffness = 10.0;
    Cloth cloth(d);
    // the two halves driven together along x
    for (int k = 0; k < d.rest.rows(); ++k) cloth.velocities()(k, 0) = d.rest(k, 0) < 0.25 ? 0.5 : -0.5;
    double shortest = 0.0;
    for (int s = 0; s < 24; ++s) {
      substep(cloth, 1.0 / 240.0, Vec3::Zero());
      for (int k = 0; k + 1 < 8; ++k) {
        shortest = std::min(shortest, edge_length(cloth.positions(), k, k + 1) / (0.5 / 7) - 1.0);
      }
    }
    if (mode == CompressionMode::kEnforce) {
      EXPECT_GT(shortest, -1e-3 - 1e-6);
    } else {
      EXPECT_LT(shortest, -0.01);
    }
  }
}

// ---------------------------------------------------------------------------------------------
// The explicit stability limit

// The step returned is stable (an undamped, perturbed cloth keeps a bounded energy over
// thousands of steps) and not far from the true limit (at 2.5x it blows up); the chain
// formula dt = L / sqrt(E / rho_line) is what the Gershgorin bound gives for a strip.
// The bound is linear: where bending dominates a soft sheet (B = 1e-3 N m here, 10x the
// default, with Y = 1000 N/m at 4.5 cm edges) the perturbed sheet crumples, triangles thin
// out under the weak subgrid compression, and the hinges' stiffness (~ 1 / height^2) outgrows
// the bound: the explicit path is then unstable at the returned step (README, limitations).
TEST(ClothExplicit, StableStepIsStableAndNearTheLimit) {
  for (InPlaneModel model : {InPlaneModel::kSprings, InPlaneModel::kMembrane}) {
    double ratio_energy[2];
    for (int run = 0; run < 2; ++run) {
      ClothDesc d = grid(12, 12, 0.5, 0.5);
      d.integrator = ClothIntegrator::kExplicit;
      d.material.model = model;
      d.material.damping = 0.0;
      d.material.strain_limit = 0.0;
      d.material.bend_stiffness = 1e-4;
      d.pinned = {0};
      Cloth cloth(d);
      cloth.positions() += random_offsets(d.rest.rows(), 1e-3, 9);
      const double e0 = cloth.elastic_energy();
      const double dt = cloth.stable_explicit_step() * (run == 0 ? 1.0 : 2.5);
      for (int s = 0; s < 3000; ++s) substep(cloth, dt, Vec3::Zero());
      ratio_energy[run] = (cloth.elastic_energy() + cloth.kinetic_energy()) / e0;
    }
    EXPECT_LT(ratio_energy[0], 2.0) << int(model);
    EXPECT_FALSE(ratio_energy[1] < 1e3) << int(model);  // grown beyond bounds (or overflowed to inf / nan)
  }
  // the default material on the default 64 x 64, 2 m cloth (reported)
  ClothDesc d = grid(64, 64, 2.0, 2.0);
  Cloth with_damping(d);
  d.material.damping = 0.0;
  Cloth without(d);
  const double h = 2.0 / 63.0, m = d.area_density * h * h;
  std::printf("  stable explicit step, default material, 64 x 64 over 2 m: %.4g s (damping 0.01 s), %.4g s (no "
              "damping); a chain's edge-crossing time sqrt(m h / E) = %.4g s\n",
              with_damping.stable_explicit_step(), without.stable_explicit_step(), std::sqrt(m * h / d.material.stretch_stiffness));
  EXPECT_GT(without.stable_explicit_step(), with_damping.stable_explicit_step());
}

// ---------------------------------------------------------------------------------------------
// Odds and ends: validation, normals

TEST(Cloth, ValidatesItsDescription) {
  const ClothDesc good = grid(3, 3, 1.0, 1.0);
  EXPECT_NO_THROW(Cloth{good});
  ClothDesc d = good;
  d.triangles(0, 1) = 99;
  EXPECT_THROW(Cloth{d}, std::invalid_argument);
  d = good;
  d.pinned = {9};
  EXPECT_THROW(Cloth{d}, std::invalid_argument);
  d = good;
  d.area_density = 0.0;
  EXPECT_THROW(Cloth{d}, std::invalid_argument);
  d = good;
  d.material.poisson_ratio = 0.7;
  EXPECT_THROW(Cloth{d}, std::invalid_argument);
  d = good;
  d.rest.row(1) = d.rest.row(0);  // a collapsed triangle
  d.rest.row(3) = d.rest.row(0);
  EXPECT_THROW(Cloth{d}, std::invalid_argument);
  d = good;
  d.rest.conservativeResize(10, 3);
  d.rest.row(9) << 5, 5, 5;  // a vertex in no triangle
  EXPECT_THROW(Cloth{d}, std::invalid_argument);
}

TEST(Cloth, NormalsMassesAndPinnedState) {
  ClothDesc d = grid(4, 4, 0.3, 0.3);
  d.pinned = {5};
  Cloth cloth(d);
  EXPECT_NEAR(cloth.masses().sum(), d.area_density * 0.09, 1e-15);
  const Points n = cloth.vertex_normals();
  for (int k = 0; k < n.rows(); ++k) EXPECT_NEAR(n(k, 1), 1.0, 1e-12);  // (p00, p01, p11) winds up +y
  cloth.velocities().setConstant(1.0);
  substep(cloth, 0.01, Vec3(0, -9.81, 0));
  EXPECT_EQ(row(cloth.positions(), 5), row(d.rest, 5));
  EXPECT_EQ(cloth.vertex_count(), 16);
  EXPECT_NEAR(cloth.potential_energy(Vec3(0, -9.81, 0)), 9.81 * cloth.masses().dot(cloth.positions().col(1)), 1e-12);
}

// ---------------------------------------------------------------------------------------------
// (9) contacts held inside the velocity update

// Constraint filtering (Baraff and Witkin 1998, 5.3) on a stretched, bent, moving sheet, with
// either preconditioner and both integrators: a held vertex leaves the update with exactly the
// velocity asked along its normal (its component is fixed before the solve and never searched,
// so only round-off, 1e-15 m/s, may change it), and momentum balances: with nothing pinned
// the internal forces sum to zero, so the cloth's momentum changes by gravity's impulse plus
// the impulses the update reports along the normals. The solve's residual in the free
// directions bounds the mismatch: 1e-10 of the right-hand side, which the elastic impulses of
// the 5% stretch make ~1e3 times gravity's here, over 432 unknowns: at most ~2e-6 of the
// gravity impulse (measured 1.5e-8); 1e-6 asked.
TEST(ClothContactConstraints, HoldTheirVerticesAndBalanceMomentum) {
  const Vec3 gravity(0.0, -9.81, 0.0);
  const double dt = 1.0 / 120.0;
  for (ClothIntegrator integrator : {ClothIntegrator::kImplicit, ClothIntegrator::kExplicit}) {
    for (ClothPreconditioner preconditioner : {ClothPreconditioner::kBlockJacobi, ClothPreconditioner::kMultigrid}) {
      if (integrator == ClothIntegrator::kExplicit && preconditioner == ClothPreconditioner::kMultigrid) continue;
      ClothDesc d = grid(12, 12, 0.5, 0.5);
      d.tolerance = 1e-10;
      d.integrator = integrator;
      d.preconditioner = preconditioner;
      d.material.stretch_stiffness = 500.0;
      d.material.bend_stiffness = 1e-3;
      Cloth cloth(d);
      cloth.positions() = 1.05 * d.rest + random_offsets(d.rest.rows(), 0.01, 11);
      cloth.velocities() = random_offsets(d.rest.rows(), 0.3, 12);
      const Points v0 = cloth.velocities();
      std::vector<ClothContactConstraint> constraints;
      std::mt19937 random(13);
      std::normal_distribution<double> normal(0.0, 1.0);
      for (int k : {3, 17, 40, 41, 77, 100, 143}) {
        const Vec3 n = Vec3(normal(random), normal(random), normal(random)).normalized();
        ClothContactConstraint c;
        c.vertex = k;
        c.normal = n;
        c.speed = 0.2 * normal(random);
        constraints.push_back(c);
      }
      cloth.update_velocities(dt, gravity, &constraints);
      const Points& v = cloth.velocities();
      Vec3 change = Vec3::Zero(), expected = Vec3::Zero();
      for (int k = 0; k < v.rows(); ++k) {
        change += cloth.masses()[k] * (row(v, k) - row(v0, k));
        expected += cloth.masses()[k] * dt * gravity;
      }
      const double gravity_impulse = expected.norm();
      for (const ClothContactConstraint& c : constraints) {
        EXPECT_NEAR(row(v, c.vertex).dot(c.normal), c.speed, 1e-12) << c.vertex;
        expected += c.impulse * c.normal;
      }
      EXPECT_LT((change - expected).norm(), 1e-6 * gravity_impulse)
          << int(integrator) << " " << int(preconditioner) << ": " << (change - expected).transpose();
    }
  }
}

// A held vertex whose neighbours pull it off the surface reports a negative impulse (the
// surface would have to pull), one pressed onto it a positive one: a sheet at rest, its
// middle vertex held along +y, with gravity down (the surface carries it) and up (it would
// have to hold it down).
TEST(ClothContactConstraints, ReportWhetherTheSurfacePushesOrPulls) {
  for (double g : {-9.81, 9.81}) {
    ClothDesc d = grid(9, 9, 0.4, 0.4);
    Cloth cloth(d);
    std::vector<ClothContactConstraint> constraints(1);
    constraints[0].vertex = 40;
    cloth.update_velocities(1.0 / 120.0, Vec3(0.0, g, 0.0), &constraints);
    if (g < 0.0) {
      EXPECT_GT(constraints[0].impulse, 0.0);
    } else {
      EXPECT_LT(constraints[0].impulse, 0.0);
    }
  }
}
