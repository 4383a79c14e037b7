// The cloth's internal forces, element by element, and their assembly over a whole cloth.
// Private to core/cloth (Cloth uses it; the tests check it against finite differences);
// the formulas and the papers they come from are described at the top of cloth_forces.cpp.
//
// Conventions: every element function works on the energy W of one element. "gradient" is
// dW/dx (the force is its negative); "hessian" is d2W/dx2 (the force Jacobian K = df/dx is
// its negative). Local vertex order: spring (i, j); triangle (0, 1, 2); hinge (0, 1) the
// shared edge, 2 the opposite vertex of the triangle in which the edge runs 0 -> 1, 3 the
// opposite vertex of the other triangle.
#pragma once

#include "cloth/cloth.h"
#include "math/types.h"

#include <Eigen/Sparse>

#include <vector>

namespace simbake::cloth_detail {

using Vec6 = Eigen::Matrix<double, 6, 1>;
using Mat6 = Eigen::Matrix<double, 6, 6>;
using Vec9 = Eigen::Matrix<double, 9, 1>;
using Mat9 = Eigen::Matrix<double, 9, 9>;
using Vec12 = Eigen::Matrix<double, 12, 1>;
using Mat12 = Eigen::Matrix<double, 12, 12>;

// ---- springs: W = 1/2 s E (|A| - 1)^2 L, A = (x_j - x_i) / L, s = compress_scale when |A| < 1

double spring_energy(const Vec3& xi, const Vec3& xj, double rest, double stiffness, double compress_scale);
// gradient (6); hessian: the exact one with the transverse term clamped at zero (so it is
// positive semi-definite; exact in tension); material: the part along the edge only,
// s E / L d d^T, which is what damping uses (zero on rigid motion). Any output may be null.
void spring_terms(const Vec3& xi, const Vec3& xj, double rest, double stiffness, double compress_scale,
                  Vec6* gradient, Mat6* hessian, Mat6* material);

// ---- membrane: St. Venant-Kirchhoff on the Green strain of a linear triangle

struct MembraneRest {
  Eigen::Matrix2d dm_inverse;  // inverse of the rest edge matrix in the triangle's own 2D frame
  double area = 0.0;           // rest area (m^2)
};
MembraneRest membrane_rest(const Vec3& x0, const Vec3& x1, const Vec3& x2);

// Plane-stress Lame parameters of a sheet with Y = Young's modulus x thickness (N/m)
struct Lame {
  double mu = 0.0, lambda = 0.0;
};
Lame lame_parameters(double stretch_stiffness, double poisson_ratio);

double membrane_energy(const Vec3& x0, const Vec3& x1, const Vec3& x2, const MembraneRest& rest,
                       const Lame& lame, double compress_scale);
// gradient (9); hessian: exact (may be indefinite under compression); material: the
// Gauss-Newton part (dG/dx)^T C (dG/dx) A, positive semi-definite and zero on rigid motion.
void membrane_terms(const Vec3& x0, const Vec3& x1, const Vec3& x2, const MembraneRest& rest,
                    const Lame& lame, double compress_scale, Vec9* gradient, Mat9* hessian, Mat9* material);
// The nearest positive semi-definite matrix (negative eigenvalues set to zero)
Mat9 project_psd(const Mat9& m);

// ---- bending: W = 1/2 k (theta - theta0)^2 per hinge, k = B |e|^2 / (A1 + A2) (rest values)

// signed dihedral angle across the edge (x0, x1) (0 when flat; radians, in (-pi, pi])
double dihedral_angle(const Vec3& x0, const Vec3& x1, const Vec3& x2, const Vec3& x3);
// its gradient (12), closed form (Bridson, Marino and Fedkiw 2003; Grinspun et al. 2003)
Vec12 dihedral_angle_gradient(const Vec3& x0, const Vec3& x1, const Vec3& x2, const Vec3& x3);
// theta - theta0 wrapped into (-pi, pi]
double angle_difference(double theta, double theta0);

// ---- a whole cloth

struct Edge {
  int i = 0, j = 0;        // i < j
  double rest = 0.0;       // rest length (m)
  double stiffness = 0.0;  // the spring's E (N): 12/5 x the sheet's stretch_stiffness (N/m)
                           // x the edge's share of the rest area (a third of each of its
                           // triangles) / its rest length, so a refined mesh is the same sheet
};
struct Hinge {
  int v[4] = {0, 0, 0, 0};  // see the local order at the top of this file
  double rest_angle = 0.0;  // dihedral angle of the rest mesh (rad)
  double weight = 0.0;      // |e|^2 / (A1 + A2) of the rest mesh (dimensionless)
};
struct MembraneElement {
  int v[3] = {0, 0, 0};
  MembraneRest rest;
};

class ForceModel;

// The fixed sparsity pattern of a cloth's system matrix: 3x3 blocks for every pair of
// vertices that share an element (spring, triangle or hinge), over the vertices in the matrix
// (vertex -> block index, -1 for vertices left out: pinned). Built once per cloth, so that
// each substep writes straight into a matrix's values (no triplets to sort) and a direct
// solver can keep its symbolic analysis.
class MatrixPattern {
 public:
  MatrixPattern(const ForceModel& model, const std::vector<int>& matrix_index);
  // a zero matrix with the pattern (full symmetric storage, column-major)
  Eigen::SparseMatrix<double> make_matrix() const;
  // slots of element e's N x N blocks, row-major over its local vertices: the position of
  // the block's first row inside each of its three columns, -1 if either vertex is left out
  const int* edge_slots(size_t e) const { return &edge_slots_[4 * e]; }
  const int* membrane_slots(size_t e) const { return &membrane_slots_[9 * e]; }
  const int* hinge_slots(size_t e) const { return &hinge_slots_[16 * e]; }
  const std::vector<int>& matrix_index() const { return index_; }

 private:
  std::vector<int> index_;
  Eigen::SparseMatrix<double> pattern_;
  std::vector<int> edge_slots_, membrane_slots_, hinge_slots_;
};

// What to assemble at positions x. Every output is optional (null: skipped).
struct Assembly {
  bool stretch = true, bend = true;  // which elements take part
  bool elastic = true;               // force += -dW/dx
  const Points* velocity = nullptr;  // needed by damping
  double damping = 0.0;              // force += -damping * H_material v (Rayleigh, stiffness-proportional)
  const Points* material_at = nullptr;  // where H_material is evaluated (damping's force and matrix); null: x
  double hessian_weight = 0.0;       // matrix += hessian_weight * H (clamped, PSD)
  double material_weight = 0.0;      // matrix += material_weight * H_material
  Eigen::VectorXd* force = nullptr;  // (3n) += internal forces
  // matrix += the weighted Hessians, into a matrix made by pattern->make_matrix()
  const MatrixPattern* pattern = nullptr;
  Eigen::SparseMatrix<double>* matrix = nullptr;
};

// Topology, rest state and material of a cloth: constant once built
class ForceModel {
 public:
  ForceModel(const Points& rest, const Triangles& triangles, const ClothMaterial& material);

  const std::vector<Edge>& edges() const { return edges_; }
  const std::vector<Hinge>& hinges() const { return hinges_; }
  const std::vector<MembraneElement>& membranes() const { return membranes_; }
  const Lame& lame() const { return lame_; }
  double compress_scale() const { return compress_scale_; }

  double stretch_energy(const Points& x) const;  // springs or membrane
  double bend_energy(const Points& x) const;
  void assemble(const Points& x, const Assembly& what) const;

 private:
  ClothMaterial material_;
  Lame lame_;
  double compress_scale_ = 1.0;  // stiffness multiplier under compression
  std::vector<Edge> edges_;
  std::vector<Hinge> hinges_;
  std::vector<MembraneElement> membranes_;
};

}  // namespace simbake::cloth_detail
