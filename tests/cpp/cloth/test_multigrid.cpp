// The implicit cloth step's preconditioners (cloth/multigrid.h) on the step's own system,
// assembled as Cloth::implicit_velocities assembles it (M + dt^2 H + c dt H_m, scaled by
// M^-1/2): conjugate gradients preconditioned by multigrid reach the direct solution
// (SimplicialLDLT) within the bound the residual gives; with Baraff-Witkin's filter too; the
// iteration count stays nearly flat under refinement where block-Jacobi's grows; a cloth
// stepped with either preconditioner ends in the same place.
#include <gtest/gtest.h>

#include "cloth/cloth.h"
#include "cloth/cloth_forces.h"
#include "cloth/lower_kernels.h"
#include "cloth/multigrid.h"
#include "test_support.h"

#include <Eigen/SVD>
#include <Eigen/SparseCholesky>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <random>

using namespace simbake;
using namespace simbake::cloth_detail;

namespace {

constexpr double kDt = 1.0 / 120.0;  // the drape's cloth step (s)

// One implicit step's scaled system A z = b (z = M^1/2 dv) over the free vertices, with
// what a multigrid needs: the free vertices' edge graph and sqrt(m)
struct System {
  Eigen::SparseMatrix<double> a;
  Eigen::VectorXd b, scale;
  std::vector<std::vector<int>> graph;
};

// The drape's material (benchmarks/cloth/drape_spec.py): 2000 N/m springs, 0.1 kg/m^2
ClothMaterial drape_material() {
  ClothMaterial m;
  m.stretch_stiffness = 2000.0;
  m.bend_stiffness = 1e-4;
  m.damping = 0.01;
  return m;
}

System assemble(const Points& rest, const Triangles& triangles, const Points& x, const Points& v,
                const std::vector<char>& pinned, const ClothMaterial& material) {
  const int n = static_cast<int>(rest.rows());
  Eigen::VectorXd mass = Eigen::VectorXd::Zero(n);
  for (int t = 0; t < triangles.rows(); ++t) {
    const Vec3 a = rest.row(triangles(t, 0)), b = rest.row(triangles(t, 1)), c = rest.row(triangles(t, 2));
    for (int k = 0; k < 3; ++k) mass[triangles(t, k)] += 0.1 * 0.5 * (b - a).cross(c - a).norm() / 3.0;
  }
  std::vector<int> index(n, -1);
  int free = 0;
  for (int k = 0; k < n; ++k) {
    if (!pinned[k] && mass[k] > 0.0) index[k] = free++;
  }
  const ForceModel model(rest, triangles, material);
  const MatrixPattern pattern(model, index);
  System s;
  s.a = pattern.make_matrix();
  Eigen::VectorXd force = Eigen::VectorXd::Zero(3 * n);
  Assembly what;
  what.hessian_weight = kDt * kDt;
  what.force = &force;
  what.pattern = &pattern;
  what.matrix = &s.a;
  model.assemble(x, what);
  Assembly damping;
  damping.elastic = false;
  damping.velocity = &v;
  damping.damping = material.damping;
  damping.material_weight = material.damping * kDt;
  damping.force = &force;
  damping.pattern = &pattern;
  damping.matrix = &s.a;
  model.assemble(x, damping);
  s.b.resize(3 * free);
  s.scale.resize(free);
  Eigen::VectorXd unit(3 * free);
  for (int k = 0; k < n; ++k) {
    const int i = index[k];
    if (i < 0) continue;
    s.scale[i] = std::sqrt(mass[k]);
    for (int r = 0; r < 3; ++r) {
      s.a.coeffRef(3 * i + r, 3 * i + r) += mass[k];
      unit[3 * i + r] = 1.0 / s.scale[i];
      s.b[3 * i + r] = kDt * (force[3 * k + r] + mass[k] * (r == 1 ? -9.81 : 0.0)) * unit[3 * i + r];
    }
  }
  for (int col = 0; col < s.a.outerSize(); ++col) {
    for (Eigen::SparseMatrix<double>::InnerIterator it(s.a, col); it; ++it) it.valueRef() *= unit[it.row()] * unit[col];
  }
  s.graph.resize(free);
  for (const Edge& e : model.edges()) {
    if (index[e.i] < 0 || index[e.j] < 0) continue;
    s.graph[index[e.i]].push_back(index[e.j]);
    s.graph[index[e.j]].push_back(index[e.i]);
  }
  return s;
}

// A square sheet of side 2 m with n x n vertices (a grid, or with `irregular` its interior
// vertices moved by up to 0.3 h, each square's diagonal either way and a square hole),
// draped: bent over a cylinder of radius 0.6 m, stretched 3%, with a bump and a little
// noise, moving; pinned at two corners (and the vertices the hole leaves alone)
System draped_sheet(int n, bool irregular, const ClothMaterial& material = drape_material()) {
  ClothDesc d = test::grid_cloth(n, n, 2.0, 2.0, Vec3(-1.0, 0.0, -1.0));
  const double h = 2.0 / (n - 1);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<char> pinned(n * n, 0);
  pinned[0] = pinned[n - 1] = 1;
  if (irregular) {
    for (int j = 1; j + 1 < n; ++j) {
      for (int i = 1; i + 1 < n; ++i) {
        d.rest(j * n + i, 0) += 0.3 * h * u(rng);
        d.rest(j * n + i, 2) += 0.3 * h * u(rng);
      }
    }
    std::vector<Eigen::Vector3i> kept;
    for (int j = 0; j + 1 < n; ++j) {
      for (int i = 0; i + 1 < n; ++i) {
        const double cx = (i + 0.5) / (n - 1), cz = (j + 0.5) / (n - 1);
        if (cx > 0.55 && cx < 0.75 && cz > 0.3 && cz < 0.5) continue;  // the hole
        const int p00 = j * n + i, p10 = p00 + 1, p01 = p00 + n, p11 = p01 + 1;
        if (u(rng) > 0.0) {
          kept.emplace_back(p00, p01, p11);
          kept.emplace_back(p00, p11, p10);
        } else {
          kept.emplace_back(p00, p01, p10);
          kept.emplace_back(p10, p01, p11);
        }
      }
    }
    d.triangles.resize(static_cast<int>(kept.size()), 3);
    for (size_t t = 0; t < kept.size(); ++t) d.triangles.row(static_cast<int>(t)) = kept[t].transpose();
  }
  Points x(n * n, 3), v(n * n, 3);
  const double radius = 0.6;
  for (int k = 0; k < n * n; ++k) {
    const double s = 1.03 * d.rest(k, 0), w = 1.03 * d.rest(k, 2);
    x.row(k) << radius * std::sin(s / radius), radius * (std::cos(s / radius) - 1.0) + 0.05 * std::exp(-4.0 * w * w),
        w;
    x.row(k) += 1e-3 * h * Vec3(u(rng), u(rng), u(rng)).transpose();
    v.row(k) << 0.1 * w, -0.5 + 0.2 * s, 0.0;
  }
  return assemble(d.rest, d.triangles, x, v, pinned, material);
}

// Baraff-Witkin's filter: per block, project out the constrained directions
struct Filter {
  std::vector<Mat3, Eigen::aligned_allocator<Mat3>> s;  // (blocks) I, I - n n^T or 0
  Eigen::VectorXd operator()(const Eigen::VectorXd& r) const {
    Eigen::VectorXd out(r.size());
    for (size_t i = 0; i < s.size(); ++i) out.segment<3>(3 * i) = s[i] * r.segment<3>(3 * i);
    return out;
  }
};

// Preconditioned conjugate gradients from zero to |r| <= tolerance |b| (Baraff and Witkin's
// modified PCG when a filter is given: residuals and search directions filtered, the
// preconditioner applied before the filter). Returns the iterations.
int pcg(const Eigen::SparseMatrix<double>& a, const Eigen::VectorXd& b, const Preconditioner& p, double tolerance,
        Eigen::VectorXd& z, const Filter* filter = nullptr) {
  auto f = [&](const Eigen::VectorXd& r) { return filter ? (*filter)(r) : r; };
  z = Eigen::VectorXd::Zero(b.size());
  Eigen::VectorXd r = f(b), c, q, s;
  const double goal = tolerance * r.norm();
  p.apply(r, s);
  c = f(s);
  double delta = r.dot(c);
  for (int it = 0; it < 1000; ++it) {
    if (r.norm() <= goal) return it;
    q = f(a * c);
    const double alpha = delta / c.dot(q);
    z += alpha * c;
    r -= alpha * q;
    p.apply(r, s);
    s = f(s);
    const double next = r.dot(s);
    c = s + (next / delta) * c;
    delta = next;
  }
  return 1000;
}

}  // namespace

// The multigrid-preconditioned solve against a direct one (SimplicialLDLT on the same
// matrix), on a draped grid and a draped irregular mesh with a hole and pins. A = I + (PSD)
// in the scaled unknowns, so its smallest eigenvalue is >= 1 and the error is bounded by
// the residual: |z - z*| <= |A^-1| |r| <= |r| <= tolerance |b|. Asserted at 1e-3 (the
// cloth's tolerance) and 1e-8.
TEST(ClothMultigrid, SolveMatchesDirectSolve) {
  for (bool irregular : {false, true}) {
    const System s = draped_sheet(33, irregular);
    Multigrid mg(s.a, s.graph, s.scale);
    mg.update(s.a);
    EXPECT_GE(mg.levels(), 2);
    const Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> direct(s.a);
    const Eigen::VectorXd exact = direct.solve(s.b);
    for (double tolerance : {1e-3, 1e-8}) {
      Eigen::VectorXd z;
      const int iterations = pcg(s.a, s.b, mg, tolerance, z);
      const double error = (z - exact).norm() / s.b.norm();
      std::printf("  %s 33 x 33, %d levels: %d iterations to %g, error %.2e |b|\n", irregular ? "irregular" : "grid",
                  mg.levels(), iterations, tolerance, error);
      EXPECT_LE(error, tolerance);
      EXPECT_LT(iterations, 40);
    }
  }
}

// The same with Baraff-Witkin's filter after the preconditioner: every fifth vertex may not
// move along a fixed direction, every 31st not at all. The reference solves the filtered
// system (S A S + I - S) z = S b directly, whose solution has (I - S) z = 0 and S (A z - b) = 0.
TEST(ClothMultigrid, FilteredSolveMatchesDirectSolve) {
  const System s = draped_sheet(33, true);
  const int blocks = static_cast<int>(s.scale.size());
  Filter filter;
  filter.s.assign(blocks, Mat3::Identity());
  for (int i = 0; i < blocks; i += 5) {
    const Vec3 n = Vec3(0.3, 1.0, -0.2 + 0.01 * (i % 7)).normalized();
    filter.s[i] = Mat3::Identity() - n * n.transpose();
  }
  for (int i = 0; i < blocks; i += 31) filter.s[i].setZero();
  std::vector<Eigen::Triplet<double>> entries;
  Eigen::SparseMatrix<double> sd(3 * blocks, 3 * blocks), id(3 * blocks, 3 * blocks);
  for (int i = 0; i < blocks; ++i) {
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) entries.emplace_back(3 * i + r, 3 * i + c, filter.s[i](r, c));
    }
  }
  sd.setFromTriplets(entries.begin(), entries.end());
  id.setIdentity();
  const Eigen::SparseMatrix<double> filtered = Eigen::SparseMatrix<double>(sd * s.a * sd) + id - sd;
  const Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> direct(filtered);
  const Eigen::VectorXd exact = direct.solve(filter(s.b));
  // the filtered matrix in A's own pattern: blocks S_i A_ij S_j, plus I - S_i on the diagonal
  Eigen::SparseMatrix<double> in_pattern = s.a;
  for (int col = 0; col < blocks; ++col) {
    const int* outer = in_pattern.outerIndexPtr();
    const int stride = outer[3 * col + 1] - outer[3 * col];
    for (int k = outer[3 * col]; k < outer[3 * col + 1]; k += 3) {
      const int row = in_pattern.innerIndexPtr()[k] / 3;
      double* v = in_pattern.valuePtr() + k;
      Mat3 block;
      for (int c = 0; c < 3; ++c) {
        for (int r = 0; r < 3; ++r) block(r, c) = v[c * stride + r];
      }
      block = filter.s[row] * block * filter.s[col];
      if (row == col) block += Mat3::Identity() - filter.s[col];
      for (int c = 0; c < 3; ++c) {
        for (int r = 0; r < 3; ++r) v[c * stride + r] = block(r, c);
      }
    }
  }
  for (bool aware : {false, true}) {
    Multigrid mg(s.a, s.graph, s.scale);
    mg.update(aware ? in_pattern : s.a);
    for (double tolerance : {1e-3, 1e-8}) {
      Eigen::VectorXd z;
      const int iterations = pcg(s.a, s.b, mg, tolerance, z, &filter);
      const double error = (z - exact).norm() / filter(s.b).norm();
      std::printf("  filtered, preconditioner of %s: %d iterations to %g, error %.2e |Sb|, constrained part %.1e\n",
                  aware ? "S A S + I - S" : "A", iterations, tolerance, error, (z - filter(z)).norm());
      EXPECT_LE(error, tolerance);
      EXPECT_LT((z - filter(z)).norm(), 1e-12 * z.norm());
      EXPECT_LT(iterations, aware ? 30 : 200);
    }
  }
}

// Iterations to the cloth's tolerance (1e-3) on the same draped sheet at 33, 65 and 129
// vertices a side. Block-Jacobi's grow ~1/h (the condition number grows as 1/h^2, CG's
// count as its square root); multigrid's should not grow with h at all (the smoothers take
// out the rough error at every level, the coarsest level is solved exactly), but the
// aggregates' piecewise approximation of the in-plane rotations (only translations are
// reproduced exactly) loses a little per added level: asserted at most 1.6x from 33 to 129
// (two more levels), against block-Jacobi's >= 3x.
TEST(ClothMultigrid, IterationsStayNearlyFlatUnderRefinement) {
  std::vector<int> mg_iterations, bj_iterations;
  for (int n : {33, 65, 129}) {
    const System s = draped_sheet(n, false);
    Multigrid mg(s.a, s.graph, s.scale);
    mg.update(s.a);
    BlockJacobi bj;
    bj.update(s.a);
    Eigen::VectorXd z;
    mg_iterations.push_back(pcg(s.a, s.b, mg, 1e-3, z));
    bj_iterations.push_back(pcg(s.a, s.b, bj, 1e-3, z));
    std::printf("  %d x %d (%d levels): multigrid %d iterations, block-Jacobi %d\n", n, n, mg.levels(),
                mg_iterations.back(), bj_iterations.back());
  }
  EXPECT_LE(mg_iterations[2], 1.6 * mg_iterations[0]);
  EXPECT_LE(mg_iterations[1], 1.6 * mg_iterations[0]);
  EXPECT_GE(bj_iterations[2], 3 * bj_iterations[0]);
}

// A V-cycle is a fixed sequence of operations: the same input gives the same bits, and a
// clone (a copied Cloth's) gives the same bits as the original.
TEST(ClothMultigrid, ApplyIsDeterministic) {
  const System s = draped_sheet(33, true);
  Multigrid mg(s.a, s.graph, s.scale);
  mg.update(s.a);
  const std::unique_ptr<Preconditioner> copy = mg.clone();
  Eigen::VectorXd z1, z2, z3;
  mg.apply(s.b, z1);
  mg.apply(s.b, z2);
  copy->apply(s.b, z3);
  EXPECT_EQ(0, std::memcmp(z1.data(), z2.data(), sizeof(double) * z1.size()));
  EXPECT_EQ(0, std::memcmp(z1.data(), z3.data(), sizeof(double) * z1.size()));
}

// The product from the lower triangle in single precision (what the conjugate gradients
// multiply by on large systems) against Eigen's full double product of the same matrix:
// each block is rounded to 2^-24 relative, so every component of A x is within a few
// 1e-8 of sum_j |A_ij| |x_j| (asserted at 1e-6 of it); x . A x as well, against |x|^T |A| |x|.
TEST(ClothMultigrid, LowerTriangleProductMatchesFullProduct) {
  for (bool irregular : {false, true}) {
    const System s = draped_sheet(33, irregular);
    BlockJacobi bj;
    bj.update(s.a);
    std::mt19937 rng(3);
    std::normal_distribution<double> g;
    Eigen::VectorXd x(s.b.size()), y;
    for (Eigen::Index k = 0; k < x.size(); ++k) x[k] = g(rng);
    const double xax = lower_product(bj.matrix(), x, y);
    const Eigen::VectorXd exact = s.a * x;
    const Eigen::SparseMatrix<double> magnitude = s.a.cwiseAbs();
    const Eigen::VectorXd bound = magnitude * x.cwiseAbs();
    const double worst = ((y - exact).cwiseAbs().array() / bound.array()).maxCoeff();
    const double dot_error = std::abs(xax - x.dot(exact)) / x.cwiseAbs().dot(bound);
    std::printf("  %s: largest error %.2e of sum |A_ij x_j|, x . A x %.2e of |x| |A| |x|\n",
                irregular ? "irregular" : "grid", worst, dot_error);
    EXPECT_LT(worst, 1e-6);
    EXPECT_LT(dot_error, 1e-6);
  }
}

// A V-cycle must be a symmetric positive definite map for the conjugate gradients: its
// backward sweep the adjoint of its forward one. Checked on random vectors u, w of the
// draped irregular mesh's system: u . P w = w . P u to round-off (the V-cycle works in double
// on a fixed single-precision matrix: 1e-9 relative asserted), and u . P u > 0.
TEST(ClothMultigrid, VCycleIsSymmetricPositiveDefinite) {
  const System s = draped_sheet(65, true);
  Multigrid mg(s.a, s.graph, s.scale);
  mg.update(s.a);
  ASSERT_GE(mg.levels(), 3);
  std::mt19937 rng(11);
  std::normal_distribution<double> g;
  for (int trial = 0; trial < 5; ++trial) {
    Eigen::VectorXd u(s.b.size()), w(s.b.size()), pu, pw;
    for (Eigen::Index k = 0; k < u.size(); ++k) {
      u[k] = g(rng);
      w[k] = g(rng);
    }
    mg.apply(u, pu);
    mg.apply(w, pw);
    const double asymmetry = std::abs(u.dot(pw) - w.dot(pu)) / (u.norm() * pw.norm());
    EXPECT_LT(asymmetry, 1e-9) << "trial " << trial;
    EXPECT_GT(u.dot(pu), 0.0);
    if (trial == 0) std::printf("  |u . P w - w . P u| / (|u| |P w|) = %.2e\n", asymmetry);
  }
}

// The finest level's smoother (multigrid.cpp, "The smoother") keeps every block between
// mesh-edge neighbours and drops the others (bending's couplings across hinges) where that
// distorts neither row much, adding their norms to the diagonals, so that its matrix S
// satisfies u . S u >= u . A u for every u (S - A positive semi-definite: the V-cycle's
// smoother then converges and the cycle stays positive definite, the test above). On the
// draped sheet with the drape's bending (1e-4 N m) and with a stiff one (0.05 N m, where
// bending's couplings are as large as the diagonals' smallest eigenvalues and rows keep
// them). Checked on random vectors and on the worst case for the largest dropped block A_ij:
// u_i, u_j its singular vectors, signed to make u . A u largest.
TEST(ClothMultigrid, SmootherKeepsEdgeBlocksAndDominatesTheSystem) {
  for (double bend : {1e-4, 5e-2}) {
    ClothMaterial material = drape_material();
    material.bend_stiffness = bend;
    const System s = draped_sheet(65, true, material);
    Multigrid mg(s.a, s.graph, s.scale);
    mg.update(s.a);
    const BlockMatrix& a = mg.matrix();
    const LowerBlocks& smoother = mg.smoother();
    const LowerView view{a.size, smoother.start.data(), smoother.column.data(), smoother.block.data()};
    const LowerView full{a.size, a.lower.start.data(), a.lower.column.data(), a.lower.block.data()};
    const auto edge = [&](int i, int j) { return std::find(s.graph[i].begin(), s.graph[i].end(), j) != s.graph[i].end(); };
    int dropped = 0;
    Mat3 worst = Mat3::Zero();
    int worst_i = -1, worst_j = -1;
    for (int i = 0; i < a.size; ++i) {
      const std::vector<int> kept(smoother.column.begin() + smoother.start[i], smoother.column.begin() + smoother.start[i + 1] - 1);
      EXPECT_EQ(smoother.column[smoother.start[i + 1] - 1], i);
      for (int k = a.start[i]; k < a.start[i + 1]; ++k) {
        const int j = a.column[k];
        if (j >= i) continue;
        const bool in = std::find(kept.begin(), kept.end(), j) != kept.end();
        if (edge(i, j)) EXPECT_TRUE(in) << "edge block (" << i << ", " << j << ") dropped";
        if (in) continue;
        ++dropped;
        if (a.block[k].norm() > worst.norm()) {
          worst = a.block[k];
          worst_i = i;
          worst_j = j;
        }
      }
      for (int j : kept) EXPECT_LT(j, i);
    }
    EXPECT_EQ(dropped, mg.smoother_dropped());
    std::printf("  bending %g N m, 65 x 65 irregular: %d non-edge blocks dropped, %d rows keep theirs\n", bend,
                dropped, mg.smoother_full_rows());
    ASSERT_GT(dropped, 0);
    if (bend > 1e-3) EXPECT_GT(mg.smoother_full_rows(), 0);
    // u . S u - u . A u, relative to u . A u
    const auto excess = [&](const Eigen::VectorXd& u) {
      Eigen::VectorXd y(u.size());
      const double usu = lower_product(view, u.data(), y.data());
      const double uau = lower_product(full, u.data(), y.data());
      return (usu - uau) / uau;
    };
    std::mt19937 rng(5);
    std::normal_distribution<double> g;
    for (int trial = 0; trial < 5; ++trial) {
      Eigen::VectorXd u(s.b.size());
      for (Eigen::Index k = 0; k < u.size(); ++k) u[k] = g(rng);
      EXPECT_GE(excess(u), -1e-6) << "trial " << trial;
    }
    const Eigen::JacobiSVD<Mat3> svd(worst, Eigen::ComputeFullU | Eigen::ComputeFullV);
    double e = 1e300;
    for (double sign : {1.0, -1.0}) {
      Eigen::VectorXd u = Eigen::VectorXd::Zero(s.b.size());
      u.segment<3>(3 * worst_i) = svd.matrixU().col(0);
      u.segment<3>(3 * worst_j) = sign * svd.matrixV().col(0);
      e = std::min(e, excess(u));
    }
    std::printf("  largest dropped block |A_ij| = %.3g; along its singular vectors u . (S - A) u / u . A u = %.3g\n",
                svd.singularValues()[0], e);
    EXPECT_GE(e, -1e-6);
  }
}

// The product and the V-cycle (its sweeps) built for AVX2 and in plain C++ do the same IEEE
// operations in the same order (lower_kernels.h): the same bits, on the draped irregular
// mesh's system and on random vectors (skipped where the processor has no AVX2).
TEST(LowerKernels, AvxAndPlainGiveTheSameBits) {
  if (!avx2_available()) GTEST_SKIP() << "no AVX2 here";
  const System s = draped_sheet(65, true);
  Multigrid mg(s.a, s.graph, s.scale);
  mg.update(s.a);
  std::mt19937 rng(5);
  std::normal_distribution<double> g;
  Eigen::VectorXd x(s.b.size());
  for (Eigen::Index k = 0; k < x.size(); ++k) x[k] = g(rng);
  Eigen::VectorXd y[2], z[2];
  double xax[2];
  for (int plain = 0; plain < 2; ++plain) {
    const bool before = use_avx2(plain == 0);
    xax[plain] = lower_product(mg.matrix(), x, y[plain]);
    mg.apply(x, z[plain]);
    use_avx2(before);
  }
  EXPECT_EQ(0, std::memcmp(y[0].data(), y[1].data(), sizeof(double) * y[0].size()));
  EXPECT_EQ(0, std::memcmp(z[0].data(), z[1].data(), sizeof(double) * z[0].size()));
  EXPECT_EQ(xax[0], xax[1]);
  EXPECT_GT((z[0] - x).norm(), 0.0);  // the cycle did something
}

// A cloth stepped with multigrid ends where the same cloth stepped with block-Jacobi ends,
// at a tight tolerance (1e-9, so that both solves are exact to ~1e-9 of each step's
// velocity change): a 25 x 25 sheet pinned at two corners, swinging under gravity for
// 0.25 s (30 steps of 1/120 s, strain limiting included).
TEST(ClothMultigrid, SteppedClothMatchesBlockJacobi) {
  Points end[2];
  for (int k = 0; k < 2; ++k) {
    ClothDesc d = test::grid_cloth(25, 25, 1.0, 1.0);
    d.pinned = {0, 24};
    d.material = drape_material();
    d.tolerance = 1e-9;
    d.preconditioner = k == 0 ? ClothPreconditioner::kBlockJacobi : ClothPreconditioner::kMultigrid;
    Cloth cloth(d);
    EXPECT_EQ(k == 1, cloth.uses_multigrid());
    for (int step = 0; step < 30; ++step) {
      cloth.update_velocities(kDt, Vec3(0.0, -9.81, 0.0));
      cloth.limit_strain(kDt);
      cloth.update_positions(kDt);
    }
    end[k] = cloth.positions();
    std::printf("  %s: %lld iterations in 30 steps\n", k == 0 ? "block-Jacobi" : "multigrid", cloth.solver_iterations());
  }
  const double difference = (end[0] - end[1]).cwiseAbs().maxCoeff();
  std::printf("  largest difference of the end positions %.2e m\n", difference);
  EXPECT_LT(difference, 1e-6);
}

// The automatic choice: multigrid from 1,000 free vertices, pinned or not, block-Jacobi below.
TEST(ClothMultigrid, AutomaticChoice) {
  ClothDesc big = test::grid_cloth(33, 33, 1.0, 1.0);
  EXPECT_TRUE(Cloth(big).uses_multigrid());
  big.pinned = {0};
  EXPECT_TRUE(Cloth(big).uses_multigrid());
  EXPECT_FALSE(Cloth(test::grid_cloth(17, 17, 1.0, 1.0)).uses_multigrid());
}
