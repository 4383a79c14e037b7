// Per-element energies, gradients and Hessians of the cloth (springs, StVK membrane,
// dihedral-angle bending) and their assembly.
//
// In-plane elasticity, two models behind one interface (material.model):
//  * springs (the notes, "Curve / Springs"): every mesh edge is a spring, so a grid's
//    sides resist stretch and its triangle diagonals resist shear. Per edge of rest length
//    L, A = (x_j - x_i) / L is the deformation gradient of the segment and
//        W = 1/2 E (|A| - 1)^2 L,     f_j = -E (|x_j - x_i| / L - 1) d = -f_i,
//    d the unit edge direction: a spring of constant k = E / L. E (N, force per unit
//    strain) is not the user's number: stretch_stiffness is the sheet's stiffness Y (N/m,
//    as for the membrane) and each edge gets E = 12/5 Y a / L, a its share of the rest area
//    (a third of each of its triangles), i.e. the width of sheet it stands for. A refined
//    mesh is then the same sheet, and a regular right-triangle grid pulled along an axis
//    resists with exactly Y (its sides give 1/3 and its diagonals 1/12 of Y a / L's
//    stiffness: 5/12); an equilateral mesh gives 0.8 Y in every direction.
//  * membrane (the notes, "Elastic Surfaces" to "Surface elasticity"): each triangle is a
//    linear element; its rest shape is laid out in its own 2D frame (Dm, 2x2) so that the
//    deformation gradient F = Ds Dm^-1 is 3x2 (Ds = [x1 - x0, x2 - x0]), the Green strain
//    G = 1/2 (F^T F - I) is 2x2, and St. Venant-Kirchhoff gives
//        W = A0 (mu G:G + lambda/2 tr(G)^2),   S = 2 mu G + lambda tr(G) I,   P = F S,
//        forces on (x1, x2) = -A0 P Dm^-T (columns), on x0 minus their sum,
//    with plane-stress Lame parameters from Y = stretch_stiffness (Young's modulus x
//    thickness, N/m) and nu = poisson_ratio: mu = Y / (2 (1 + nu)), lambda = Y nu / (1 - nu^2),
//    so that a sheet pulled one way with free sides carries S11 = Y G11 and narrows by
//    G22 = -nu G11.
// Compression (notes, "Compression and buckling", Choi and Ko 2002's subgrid idea): real cloth
// buckles instead of compressing, which a coarse mesh cannot resolve. With kSubgrid (and
// kEnforce) a spring under compression (|A| < 1) has stiffness E x subgrid_scale; the
// membrane does the same per principal Green strain (W = mu sum s(g_i) g_i^2 + lambda/2
// s(tr G) tr(G)^2, s = subgrid_scale for a negative argument, else 1), so a sheet compressed
// one way and stretched the other only resists the stretch. kNone is symmetric.
// kEnforce adds an impulse pass (below) that keeps edges from shortening at all.
//
// Bending (notes, "Bending energy"; Grinspun, Hirani, Desbrun and Schroeder 2003, "Discrete
// shells"): for each interior edge (hinge) e with current dihedral angle theta, rest angle
// theta0 (of the rest mesh, so a curved rest mesh keeps its shape), rest length |e| and the
// rest areas A1, A2 of its two triangles,
//        W_e = c B (theta - theta0)^2 |e|^2 / (A1 + A2),     c = 1/2 (not the 3/2 of the paper).
// The constant is set so that the energy of a cylinder matches the continuum 1/2 B (1/R1 +
// 1/R2)^2 = B / (2 R^2) per unit area (cloth bends isometrically, so this is the case that
// matters). Derivation: for a regular mesh bent onto a cylinder of radius R, the hinges
// along the axis between strips of width h turn by theta = h / R and the others stay flat
// (exactly so on a grid with the axis along a grid direction; on an equilateral mesh the
// sum over the three edge directions gives the same, for any axis direction). Per unit
// area there is one axial hinge per h x a, with |e|^2 / (A1 + A2) = a^2 / (a h), so the
// energy per area is c B (h/R)^2 (a / h) / (h a) = c B / R^2: c = 1/2. More generally, on
// an equilateral mesh the edge sum has the density c (H2 - 8/3 K), H2 = (1/R1 + 1/R2)^2
// and K the Gaussian curvature, whatever the orientation; the paper's 3/2 makes the H2 term
// 3x too stiff (it is calibrated on a sphere, where the K term takes the excess back). With
// 1/2 the H2 term is exact and the K term, whose integral is topological (Gauss-Bonnet),
// exerts no force inside the sheet; cloth bends nearly isometrically (K ~ 0) anyway.
// Checked by the test ClothBending.CylinderEnergyConvergesToContinuum (grid and
// equilateral meshes; the error is the boundary's, ~1/n). Note: on a grid whose diagonals
// all run one way the energy of a cylinder depends on its direction (an anisotropy of the
// mesh, not of the constant): exact when the curvature runs along a grid axis or across the
// diagonals, 3x when it runs along them, 0.75x at the least (15 degrees off the axis).
// The dihedral angle's gradient is the closed form of Bridson, Marino and Fedkiw 2003
// ("Simulation of clothing with folds and wrinkles"): opposite vertex x2 gets -n_A / h_A,
// x3 gets -n_B / h_B, the edge's vertices the rest weighted by where x2, x3 project onto the
// edge. The force is -B (theta - theta0) |e|^2 / (A1 + A2) grad theta.
//
// Damping (notes, soft constraints with Rayleigh damping): f_d = -damping x H_m v, where
// H_m is the elastic Hessian's material (Gauss-Newton) part: for springs E/L d d^T, so only
// the relative velocity along the edge is damped; for the membrane (dG/dx)^T C (dG/dx) A0,
// i.e. the strain rate; for bending grad theta grad theta^T. Each is zero for any rigid
// motion (rigid velocities change no edge length, Green strain or dihedral angle at first
// order), so a freely spinning and translating cloth keeps its momentum and energy. (The
// full Hessian would not: its geometric part times a rotation is not zero under tension.)
// H_m is evaluated at the midpoint x + dt/2 v of the step, where the velocity the step
// uses is rigid to O(a^3) for a rotation by a per step (at x it would be O(a): enough,
// times a large stiffness, to brake a spinning cloth visibly).
//
// GCC 12 reports false "may be used uninitialized" warnings inside Eigen's fixed-size
// self-adjoint eigen solver (9x9, used by project_psd); they come from Eigen's headers,
// which Eigen/Core already brought in, so the switch must precede every include.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif

#include "cloth/cloth_forces.h"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <tuple>

namespace simbake::cloth_detail {

namespace {

using Mat32 = Eigen::Matrix<double, 3, 2>;

// ---- springs

// Direction, length and strain-dependent stiffness of one spring
struct SpringGeometry {
  Vec3 d;          // unit direction i -> j
  double length;   // current length
  double strain;   // length / rest - 1
  double scale;    // compress_scale under compression, else 1
};

SpringGeometry spring_geometry(const Vec3& xi, const Vec3& xj, double rest, double compress_scale) {
  SpringGeometry g;
  const Vec3 delta = xj - xi;
  g.length = delta.norm();
  g.d = g.length > 0.0 ? Vec3(delta / g.length) : Vec3::Zero();
  g.strain = g.length / rest - 1.0;
  g.scale = g.strain < 0.0 ? compress_scale : 1.0;
  return g;
}

// ---- membrane: the response of W(G) = mu sum_i s(g_i) g_i^2 + lambda/2 s(tr G) (tr G)^2,
// g_i the principal Green strains, s(g) = compress_scale for g < 0 and 1 otherwise. With
// s = 1 it is St. Venant-Kirchhoff, W = mu G:G + lambda/2 tr(G)^2. Written through the
// eigen-decomposition so that a compressive principal direction is the soft one while the
// other one keeps its full stiffness (the sheet buckles across the compression, as the notes'
// subgrid model says); the energy stays C1 because s(g) g^2 has slope 0 at g = 0 on both sides.
struct StrainResponse {
  Eigen::Matrix2d U;     // columns: principal directions of G
  Eigen::Vector2d g;     // principal strains
  Eigen::Matrix2d gamma; // divided differences of f(g) = s(g) g: the spectral tangent factors
  double trace = 0.0;
  double trace_scale = 1.0;
  double energy = 0.0;   // density (J/m^2)
  Eigen::Matrix2d S;     // second Piola-Kirchhoff stress dW/dG (N/m)
};

StrainResponse strain_response(const Eigen::Matrix2d& G, const Lame& lame, double cs) {
  StrainResponse r;
  // closed-form eigen-decomposition of a symmetric 2x2
  const double a = G(0, 0), b = 0.5 * (G(0, 1) + G(1, 0)), d = G(1, 1);
  const double mean = 0.5 * (a + d), radius = std::hypot(0.5 * (a - d), b);
  const double phi = 0.5 * std::atan2(2.0 * b, a - d);
  r.g << mean + radius, mean - radius;
  r.U << std::cos(phi), -std::sin(phi),
         std::sin(phi), std::cos(phi);
  const auto s = [cs](double x) { return x < 0.0 ? cs : 1.0; };
  const double f0 = s(r.g[0]) * r.g[0], f1 = s(r.g[1]) * r.g[1];
  r.gamma(0, 0) = s(r.g[0]);
  r.gamma(1, 1) = s(r.g[1]);
  const double gap = r.g[0] - r.g[1];
  r.gamma(0, 1) = r.gamma(1, 0) = gap > 1e-12 ? (f0 - f1) / gap : 0.5 * (r.gamma(0, 0) + r.gamma(1, 1));
  r.trace = r.g[0] + r.g[1];
  r.trace_scale = s(r.trace);
  r.energy = lame.mu * (f0 * r.g[0] + f1 * r.g[1]) + 0.5 * lame.lambda * r.trace_scale * r.trace * r.trace;
  Eigen::Matrix2d F = Eigen::Matrix2d::Zero();
  F(0, 0) = f0;
  F(1, 1) = f1;
  r.S = 2.0 * lame.mu * r.U * F * r.U.transpose() + lame.lambda * r.trace_scale * r.trace * Eigen::Matrix2d::Identity();
  return r;
}

// dS for a change dG of the strain (the tangent C : dG)
Eigen::Matrix2d stress_change(const StrainResponse& r, const Lame& lame, const Eigen::Matrix2d& dG) {
  const Eigen::Matrix2d local = r.U.transpose() * dG * r.U;
  return 2.0 * lame.mu * r.U * local.cwiseProduct(r.gamma) * r.U.transpose() +
         lame.lambda * r.trace_scale * dG.trace() * Eigen::Matrix2d::Identity();
}

Mat32 edge_matrix(const Vec3& x0, const Vec3& x1, const Vec3& x2) {
  Mat32 ds;
  ds.col(0) = x1 - x0;
  ds.col(1) = x2 - x0;
  return ds;
}

// ---- assembly helpers

// Adds one element's force (and damping / implicit terms) and matrix blocks; `slots` are
// the element's block slots in the pattern (MatrixPattern)
template <int N>
void scatter(const int (&v)[N], const Eigen::Matrix<double, 3 * N, 1>& gradient,
             const Eigen::Matrix<double, 3 * N, 3 * N>& hessian, const Eigen::Matrix<double, 3 * N, 3 * N>& material,
             const int* slots, const Assembly& what) {
  using VecN = Eigen::Matrix<double, 3 * N, 1>;
  using MatN = Eigen::Matrix<double, 3 * N, 3 * N>;
  if (what.force != nullptr) {
    VecN f = what.elastic ? VecN(-gradient) : VecN::Zero();
    if (what.velocity != nullptr && what.damping != 0.0) {
      VecN vel;
      for (int a = 0; a < N; ++a) vel.template segment<3>(3 * a) = what.velocity->row(v[a]).transpose();
      f -= what.damping * (material * vel);
    }
    for (int a = 0; a < N; ++a) what.force->template segment<3>(3 * v[a]) += f.template segment<3>(3 * a);
  }
  if (what.matrix != nullptr && (what.hessian_weight != 0.0 || what.material_weight != 0.0)) {
    const MatN m = what.hessian_weight * hessian + what.material_weight * material;
    const std::vector<int>& index = what.pattern->matrix_index();
    const int* outer = what.matrix->outerIndexPtr();
    double* values = what.matrix->valuePtr();
    for (int a = 0; a < N; ++a) {
      for (int b = 0; b < N; ++b) {
        const int slot = slots[N * a + b];
        if (slot < 0) continue;
        for (int c = 0; c < 3; ++c) {
          double* column = values + outer[3 * index[v[b]] + c] + slot;
          for (int r = 0; r < 3; ++r) column[r] += m(3 * a + r, 3 * b + c);
        }
      }
    }
  }
}

Vec3 row(const Points& x, int k) { return x.row(k).transpose(); }

}  // namespace

// ---------------------------------------------------------------------------------------------
// Springs

double spring_energy(const Vec3& xi, const Vec3& xj, double rest, double stiffness, double compress_scale) {
  const SpringGeometry g = spring_geometry(xi, xj, rest, compress_scale);
  return 0.5 * g.scale * stiffness * g.strain * g.strain * rest;
}

void spring_terms(const Vec3& xi, const Vec3& xj, double rest, double stiffness, double compress_scale,
                  Vec6* gradient, Mat6* hessian, Mat6* material) {
  const SpringGeometry g = spring_geometry(xi, xj, rest, compress_scale);
  // dW/dx_j = s E strain d (W = 1/2 s E (l/L - 1)^2 L, dW/dl = s E strain)
  const double tension = g.scale * stiffness * g.strain;
  if (gradient != nullptr) {
    gradient->head<3>() = -tension * g.d;
    gradient->tail<3>() = tension * g.d;
  }
  if (hessian == nullptr && material == nullptr) return;
  // d2W/dx_j2 = k d d^T + (tension / l)(I - d d^T), k = s E / L; the second (geometric,
  // transverse) term is negative under compression and is dropped there
  const double k = g.scale * stiffness / rest;
  const Mat3 along = k * g.d * g.d.transpose();
  auto fill = [](Mat6* m, const Mat3& block) {
    m->topLeftCorner<3, 3>() = block;
    m->bottomRightCorner<3, 3>() = block;
    m->topRightCorner<3, 3>() = -block;
    m->bottomLeftCorner<3, 3>() = -block;
  };
  if (material != nullptr) fill(material, along);
  if (hessian != nullptr) {
    Mat3 block = along;
    if (g.length > 0.0 && tension > 0.0) block += (tension / g.length) * (Mat3::Identity() - g.d * g.d.transpose());
    fill(hessian, block);
  }
}

// ---------------------------------------------------------------------------------------------
// Membrane

MembraneRest membrane_rest(const Vec3& x0, const Vec3& x1, const Vec3& x2) {
  MembraneRest r;
  const Vec3 a = x1 - x0, b = x2 - x0;
  const Vec3 n = a.cross(b);
  const double la = a.norm(), ln = n.norm();
  if (la <= 0.0 || ln <= 0.0) {
    r.dm_inverse.setZero();
    r.area = 0.0;
    return r;
  }
  // the triangle's own frame: e1 along the first edge, e2 in the plane, both unit
  const Vec3 e1 = a / la, e2 = (n / ln).cross(e1);
  Eigen::Matrix2d dm;
  dm << la, b.dot(e1),
        0.0, b.dot(e2);
  r.dm_inverse = dm.inverse();
  r.area = 0.5 * dm.determinant();
  return r;
}

Lame lame_parameters(double stretch_stiffness, double poisson_ratio) {
  // plane stress (a thin sheet): mu = Y / (2 (1 + nu)), lambda = Y nu / (1 - nu^2); then a
  // uniaxial stress gives S11 = Y G11 exactly, and G22 = -nu G11
  Lame l;
  l.mu = stretch_stiffness / (2.0 * (1.0 + poisson_ratio));
  l.lambda = stretch_stiffness * poisson_ratio / (1.0 - poisson_ratio * poisson_ratio);
  return l;
}

double membrane_energy(const Vec3& x0, const Vec3& x1, const Vec3& x2, const MembraneRest& rest,
                       const Lame& lame, double compress_scale) {
  const Mat32 F = edge_matrix(x0, x1, x2) * rest.dm_inverse;
  const Eigen::Matrix2d G = 0.5 * (F.transpose() * F - Eigen::Matrix2d::Identity());
  return rest.area * strain_response(G, lame, compress_scale).energy;
}

void membrane_terms(const Vec3& x0, const Vec3& x1, const Vec3& x2, const MembraneRest& rest,
                    const Lame& lame, double compress_scale, Vec9* gradient, Mat9* hessian, Mat9* material) {
  const Eigen::Matrix2d& dmi = rest.dm_inverse;
  const Mat32 F = edge_matrix(x0, x1, x2) * dmi;
  const Eigen::Matrix2d G = 0.5 * (F.transpose() * F - Eigen::Matrix2d::Identity());
  const StrainResponse r = strain_response(G, lame, compress_scale);
  // dW = A S : dG = A (F S) : dF = A (F S Dm^-T) : dDs, Ds = [x1 - x0, x2 - x0]
  auto to_vertices = [](const Mat32& per_edge, auto& out) {
    out.template segment<3>(3) = per_edge.col(0);
    out.template segment<3>(6) = per_edge.col(1);
    out.template segment<3>(0) = -(per_edge.col(0) + per_edge.col(1));
  };
  if (gradient != nullptr) to_vertices(rest.area * F * r.S * dmi.transpose(), *gradient);
  if (hessian == nullptr && material == nullptr) return;
  // column by column: d(grad) = A (dF S + F dS) Dm^-T with dS = C : sym(F^T dF); the
  // material part keeps only F dS (it is (dG/dx)^T C (dG/dx) A)
  for (int k = 0; k < 9; ++k) {
    const int vertex = k / 3, axis = k % 3;
    Mat32 dds = Mat32::Zero();
    if (vertex == 0) {
      dds.row(axis).setConstant(-1.0);
    } else {
      dds(axis, vertex - 1) = 1.0;
    }
    const Mat32 dF = dds * dmi;
    const Eigen::Matrix2d FtdF = F.transpose() * dF;
    const Eigen::Matrix2d dG = 0.5 * (FtdF + FtdF.transpose());
    const Mat32 dP_material = F * stress_change(r, lame, dG);
    Vec9 column;
    if (material != nullptr) {
      to_vertices(rest.area * dP_material * dmi.transpose(), column);
      material->col(k) = column;
    }
    if (hessian != nullptr) {
      to_vertices(rest.area * (dF * r.S + dP_material) * dmi.transpose(), column);
      hessian->col(k) = column;
    }
  }
  // symmetric in exact arithmetic; remove the rounding asymmetry
  if (hessian != nullptr) *hessian = 0.5 * (*hessian + hessian->transpose()).eval();
  if (material != nullptr) *material = 0.5 * (*material + material->transpose()).eval();
}

Mat9 project_psd(const Mat9& m) {
  Eigen::SelfAdjointEigenSolver<Mat9> eigen(m);
  const Eigen::Matrix<double, 9, 1> values = eigen.eigenvalues().cwiseMax(0.0);
  return eigen.eigenvectors() * values.asDiagonal() * eigen.eigenvectors().transpose();
}

// ---------------------------------------------------------------------------------------------
// Bending

double dihedral_angle(const Vec3& x0, const Vec3& x1, const Vec3& x2, const Vec3& x3) {
  const Vec3 e = x1 - x0;
  const Vec3 nA = e.cross(x2 - x0), nB = (x3 - x0).cross(e);
  const double le = e.norm();
  if (le <= 0.0) return 0.0;
  // sin and cos of the angle between the normals, both times |nA| |nB|
  return std::atan2(nA.cross(nB).dot(e) / le, nA.dot(nB));
}

Vec12 dihedral_angle_gradient(const Vec3& x0, const Vec3& x1, const Vec3& x2, const Vec3& x3) {
  Vec12 g = Vec12::Zero();
  const Vec3 e = x1 - x0;
  const Vec3 nA = e.cross(x2 - x0), nB = (x3 - x0).cross(e);
  const double le2 = e.squaredNorm(), nA2 = nA.squaredNorm(), nB2 = nB.squaredNorm();
  if (le2 <= 0.0 || nA2 <= 0.0 || nB2 <= 0.0) return g;
  const double le = std::sqrt(le2);
  // opposite vertices move the angle along their triangle's normal over its height,
  // |e| n / |n|^2 = n_hat / h; the edge's vertices share it by where the opposite
  // vertices project onto the edge (s = 0 at x0, 1 at x1), which keeps the sum zero
  const Vec3 g2 = -le * nA / nA2, g3 = -le * nB / nB2;
  const double sA = (x2 - x0).dot(e) / le2, sB = (x3 - x0).dot(e) / le2;
  g.segment<3>(0) = -(1.0 - sA) * g2 - (1.0 - sB) * g3;
  g.segment<3>(3) = -sA * g2 - sB * g3;
  g.segment<3>(6) = g2;
  g.segment<3>(9) = g3;
  return g;
}

double angle_difference(double theta, double theta0) {
  double d = theta - theta0;
  if (d > M_PI) d -= 2.0 * M_PI;
  if (d <= -M_PI) d += 2.0 * M_PI;
  return d;
}

// ---------------------------------------------------------------------------------------------
// The whole cloth

// Springs: E = 12/5 Y a / L, so that a regular right-triangle grid pulled along an axis
// resists with exactly Y (its sides give 5/12 of the unscaled stiffness: 1/3 from the sides
// and 1/12 from the diagonals); an equilateral mesh then gives 0.8 Y, isotropically
constexpr double kSpringCalibration = 12.0 / 5.0;

ForceModel::ForceModel(const Points& rest, const Triangles& triangles, const ClothMaterial& material)
    : material_(material),
      lame_(lame_parameters(material.stretch_stiffness, material.poisson_ratio)),
      compress_scale_(material.compression == CompressionMode::kNone ? 1.0 : material.subgrid_scale) {
  // every triangle side as (low, high, triangle, opposite vertex, runs low -> high in it)
  struct Side {
    int a, b, triangle, opposite;
    bool forward;
  };
  std::vector<Side> sides;
  sides.reserve(3 * triangles.rows());
  for (int t = 0; t < triangles.rows(); ++t) {
    for (int k = 0; k < 3; ++k) {
      const int p = triangles(t, k), q = triangles(t, (k + 1) % 3), o = triangles(t, (k + 2) % 3);
      sides.push_back({std::min(p, q), std::max(p, q), t, o, p < q});
    }
  }
  std::sort(sides.begin(), sides.end(), [](const Side& l, const Side& r) {
    return std::tie(l.a, l.b, l.triangle) < std::tie(r.a, r.b, r.triangle);
  });
  // edges (sorted by vertex indices: a deterministic order), and a hinge for every edge
  // shared by exactly two triangles (non-manifold edges get no bending)
  auto area = [&](int t) {
    const Vec3 p0 = row(rest, triangles(t, 0)), p1 = row(rest, triangles(t, 1)), p2 = row(rest, triangles(t, 2));
    return 0.5 * (p1 - p0).cross(p2 - p0).norm();
  };
  for (size_t s = 0; s < sides.size();) {
    size_t end = s;
    while (end < sides.size() && sides[end].a == sides[s].a && sides[end].b == sides[s].b) ++end;
    const Side& first = sides[s];
    Edge edge{first.a, first.b, (row(rest, first.b) - row(rest, first.a)).norm()};
    double share = 0.0;  // a third of each adjacent triangle's rest area
    for (size_t t = s; t < end; ++t) share += area(sides[t].triangle) / 3.0;
    edge.stiffness = edge.rest > 0.0 ? kSpringCalibration * material.stretch_stiffness * share / edge.rest : 0.0;
    edges_.push_back(edge);
    if (end - s == 2) {
      const Side& second = sides[s + 1];
      Hinge h;
      h.v[0] = first.forward ? first.a : first.b;
      h.v[1] = first.forward ? first.b : first.a;
      h.v[2] = first.opposite;
      h.v[3] = second.opposite;
      const Vec3 p0 = row(rest, h.v[0]), p1 = row(rest, h.v[1]), p2 = row(rest, h.v[2]), p3 = row(rest, h.v[3]);
      h.rest_angle = dihedral_angle(p0, p1, p2, p3);
      const double areas = area(first.triangle) + area(second.triangle);
      h.weight = areas > 0.0 ? (p1 - p0).squaredNorm() / areas : 0.0;
      hinges_.push_back(h);
    }
    s = end;
  }
  if (material_.model == InPlaneModel::kMembrane) {
    membranes_.reserve(triangles.rows());
    for (int t = 0; t < triangles.rows(); ++t) {
      MembraneElement m;
      for (int k = 0; k < 3; ++k) m.v[k] = triangles(t, k);
      m.rest = membrane_rest(row(rest, m.v[0]), row(rest, m.v[1]), row(rest, m.v[2]));
      membranes_.push_back(m);
    }
  }
}

double ForceModel::stretch_energy(const Points& x) const {
  double w = 0.0;
  if (material_.model == InPlaneModel::kSprings) {
    for (const Edge& e : edges_) {
      w += spring_energy(row(x, e.i), row(x, e.j), e.rest, e.stiffness, compress_scale_);
    }
  } else {
    for (const MembraneElement& m : membranes_) {
      w += membrane_energy(row(x, m.v[0]), row(x, m.v[1]), row(x, m.v[2]), m.rest, lame_, compress_scale_);
    }
  }
  return w;
}

double ForceModel::bend_energy(const Points& x) const {
  if (material_.bend_stiffness == 0.0) return 0.0;
  double w = 0.0;
  for (const Hinge& h : hinges_) {
    const double d = angle_difference(
        dihedral_angle(row(x, h.v[0]), row(x, h.v[1]), row(x, h.v[2]), row(x, h.v[3])), h.rest_angle);
    w += 0.5 * material_.bend_stiffness * h.weight * d * d;
  }
  return w;
}

void ForceModel::assemble(const Points& x, const Assembly& what) const {
  const bool matrix = what.matrix != nullptr;
  const bool velocity_terms = what.force != nullptr && what.velocity != nullptr;
  // which Hessians are needed at all
  const bool need_hessian = matrix && what.hessian_weight != 0.0;
  const bool need_material = (matrix && what.material_weight != 0.0) || (velocity_terms && what.damping != 0.0);
  // the material Hessian's positions, when they are not x
  const Points* at = what.material_at;
  const bool elsewhere = at != nullptr && at != &x;

  // in-plane: springs along every edge (stretch, and shear along the diagonals)
  if (!what.stretch) {
    // (in-plane terms not asked for)
  } else if (material_.model == InPlaneModel::kSprings) {
    Vec6 gradient;
    Mat6 hessian = Mat6::Zero(), material = Mat6::Zero();
    for (const Edge& e : edges_) {
      spring_terms(row(x, e.i), row(x, e.j), e.rest, e.stiffness, compress_scale_, &gradient,
                   need_hessian ? &hessian : nullptr, need_material && !elsewhere ? &material : nullptr);
      if (need_material && elsewhere) {
        spring_terms(row(*at, e.i), row(*at, e.j), e.rest, e.stiffness, compress_scale_, nullptr, nullptr, &material);
      }
      const int v[2] = {e.i, e.j};
      scatter<2>(v, gradient, hessian, material, matrix ? what.pattern->edge_slots(&e - edges_.data()) : nullptr, what);
    }
  } else {
    // in-plane: StVK membrane per triangle, its Hessian projected to PSD
    Vec9 gradient;
    Mat9 hessian = Mat9::Zero(), material = Mat9::Zero();
    for (const MembraneElement& m : membranes_) {
      membrane_terms(row(x, m.v[0]), row(x, m.v[1]), row(x, m.v[2]), m.rest, lame_, compress_scale_, &gradient,
                     need_hessian ? &hessian : nullptr, need_material && !elsewhere ? &material : nullptr);
      if (need_material && elsewhere) {
        membrane_terms(row(*at, m.v[0]), row(*at, m.v[1]), row(*at, m.v[2]), m.rest, lame_, compress_scale_, nullptr,
                       nullptr, &material);
      }
      if (need_hessian) hessian = project_psd(hessian);
      scatter<3>(m.v, gradient, hessian, material, matrix ? what.pattern->membrane_slots(&m - membranes_.data()) : nullptr, what);
    }
  }

  // bending: W = 1/2 B w (theta - theta0)^2 per hinge; Gauss-Newton Hessian B w grad grad^T
  if (material_.bend_stiffness == 0.0 || !what.bend) return;
  const bool need_gauss_newton = need_hessian || (need_material && !elsewhere);
  const bool elastic_force = what.force != nullptr && what.elastic;
  Mat12 gauss_newton = Mat12::Zero(), material = Mat12::Zero();
  for (const Hinge& h : hinges_) {
    const Vec3 p0 = row(x, h.v[0]), p1 = row(x, h.v[1]), p2 = row(x, h.v[2]), p3 = row(x, h.v[3]);
    const double k = material_.bend_stiffness * h.weight;
    const double d = elastic_force ? angle_difference(dihedral_angle(p0, p1, p2, p3), h.rest_angle) : 0.0;
    const Vec12 grad_theta = dihedral_angle_gradient(p0, p1, p2, p3);
    if (need_gauss_newton) gauss_newton = k * grad_theta * grad_theta.transpose();
    if (need_material && elsewhere) {
      const Vec12 g = dihedral_angle_gradient(row(*at, h.v[0]), row(*at, h.v[1]), row(*at, h.v[2]), row(*at, h.v[3]));
      material = k * g * g.transpose();
    }
    scatter<4>(h.v, Vec12(k * d * grad_theta), gauss_newton, elsewhere ? material : gauss_newton,
               matrix ? what.pattern->hinge_slots(&h - hinges_.data()) : nullptr, what);
  }
}

// ---------------------------------------------------------------------------------------------
// The matrix pattern

MatrixPattern::MatrixPattern(const ForceModel& model, const std::vector<int>& matrix_index) : index_(matrix_index) {
  // every element's vertex pairs, as blocks
  std::vector<Eigen::Triplet<double>> blocks;
  auto add = [&](const int* v, int n) {
    for (int a = 0; a < n; ++a) {
      for (int b = 0; b < n; ++b) {
        if (index_[v[a]] >= 0 && index_[v[b]] >= 0) blocks.emplace_back(index_[v[a]], index_[v[b]], 1.0);
      }
    }
  };
  for (const Edge& e : model.edges()) {
    const int v[2] = {e.i, e.j};
    add(v, 2);
  }
  for (const MembraneElement& m : model.membranes()) add(m.v, 3);
  for (const Hinge& h : model.hinges()) add(h.v, 4);
  int size = 0;
  for (int i : index_) size = std::max(size, i + 1);
  Eigen::SparseMatrix<double> block_pattern(size, size);
  block_pattern.setFromTriplets(blocks.begin(), blocks.end());
  // the scalar pattern: each block a dense 3x3; a block's first row sits at 3 x its rank
  // among its block column's nonzero blocks, in each of the three columns alike
  std::vector<Eigen::Triplet<double>> entries;
  entries.reserve(9 * block_pattern.nonZeros());
  for (int b = 0; b < block_pattern.outerSize(); ++b) {
    for (Eigen::SparseMatrix<double>::InnerIterator it(block_pattern, b); it; ++it) {
      for (int c = 0; c < 3; ++c) {
        for (int r = 0; r < 3; ++r) entries.emplace_back(3 * it.row() + r, 3 * b + c, 0.0);
      }
    }
  }
  pattern_.resize(3 * size, 3 * size);
  pattern_.setFromTriplets(entries.begin(), entries.end());
  auto slot = [&](int a, int b) {  // vertex indices
    const int ia = index_[a], ib = index_[b];
    if (ia < 0 || ib < 0) return -1;
    const int* outer = block_pattern.outerIndexPtr();
    const int* rows = block_pattern.innerIndexPtr();
    const int* found = std::lower_bound(rows + outer[ib], rows + outer[ib + 1], ia);
    return 3 * static_cast<int>(found - (rows + outer[ib]));
  };
  auto slots = [&](const int* v, int n, std::vector<int>& out) {
    for (int a = 0; a < n; ++a) {
      for (int b = 0; b < n; ++b) out.push_back(slot(v[a], v[b]));
    }
  };
  for (const Edge& e : model.edges()) {
    const int v[2] = {e.i, e.j};
    slots(v, 2, edge_slots_);
  }
  for (const MembraneElement& m : model.membranes()) slots(m.v, 3, membrane_slots_);
  for (const Hinge& h : model.hinges()) slots(h.v, 4, hinge_slots_);
}

Eigen::SparseMatrix<double> MatrixPattern::make_matrix() const {
  Eigen::SparseMatrix<double> m = pattern_;
  m.coeffs().setZero();
  return m;
}

}  // namespace simbake::cloth_detail
