// Preconditioners for the implicit cloth step's conjugate gradients: z = P^-1 r on the
// step's 3x3-block system (M^-1/2 (M + dt^2 H + c dt H_m) M^-1/2 over the unpinned vertices,
// the fixed pattern of MatrixPattern). Two behind one interface:
//   BlockJacobi  the inverse of each vertex's 3x3 diagonal block; cheapest per iteration,
//                but the iteration count grows with the resolution
//   Multigrid    one V-cycle of smoothed-aggregation algebraic multigrid (multigrid.cpp, its
//                method and formulas at the top); the iteration count stays nearly flat
// A conjugate-gradient loop calls update() once per step (new values, same pattern), then
// apply() once per iteration, and multiplies by matrix(), the same system in 3x3 blocks.
// Both are symmetric positive definite linear maps, so they are valid CG preconditioners,
// also when a filter S (Baraff-Witkin's constraint projection) is applied after them:
// S P^-1 S is symmetric positive semi-definite on the filtered space. With a filter, pass
// update() the filtered matrix S A S + I - S (the same pattern, S being block diagonal)
// rather than A: the V-cycle then approximates the constrained inverse, and the filtered
// solve takes several times fewer iterations (ClothMultigrid.FilteredSolveMatchesDirectSolve).
// Private to core/cloth.
#pragma once

#include "math/types.h"

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/SparseCore>

#include <memory>
#include <type_traits>
#include <vector>

namespace simbake::cloth_detail {

// The lower triangle of a symmetric 3x3-block matrix in single precision: block row i holds
// A_ij for its columns j < i, ascending, then its diagonal A_ii last; the upper triangle is
// its transpose (A_ji = A_ij^T). What the V-cycle's sweeps and the conjugate gradients'
// products read (the latter when the solve's tolerance is 1e-5 or looser, integrators.cpp) through
// lower_kernels.h: large systems are bound by memory traffic, and a preconditioner or a
// solve to 1e-3 needs no more digits (the rounding is 1e-7 relative). Each block read serves
// its row and, transposed, its column: a product reads half the blocks of full storage, and a
// Gauss-Seidel sweep fused with the scatter of its residual (or of the rows it precedes) reads
// them once where full storage read them twice or more.
struct LowerBlocks {
  std::vector<int> start;     // (size + 1)
  std::vector<int> column;    // (entries) j < i ascending, then i
  std::vector<int> source;    // (entries) the full matrix's entry of each block
  std::vector<float> block;   // (9 entries + 1) values, 9 a block column-major, and a pad (lower_kernels.h)
};

// A symmetric 3x3-block sparse matrix, block rows in compressed form (full storage)
struct BlockMatrix {
  int size = 0;                                       // block rows (= block columns)
  std::vector<int> start;                             // (size + 1) each row's first entry
  std::vector<int> column;                            // (entries) block column, ascending per row
  std::vector<int> diagonal;                          // (size) the entry of each row's diagonal block
  std::vector<Mat3, Eigen::aligned_allocator<Mat3>> block;  // (entries) values
  LowerBlocks lower;                                  // the lower triangle in single precision
  // (entries) where each block's values sit in the Eigen matrix it is copied from
  // (copy_values): its (0, 0) entry, and the distance between its three columns there
  std::vector<int> source, stride;
};

// y = A x from A's lower triangle in single precision (summed in double): each block A_ij
// gives A_ij x_j to row i and A_ij^T x_i to row j. Returns x . A x (from the same blocks:
// sum_i x_i . A_ii x_i + 2 sum_(j < i) x_i . A_ij x_j)
double lower_product(const BlockMatrix& a, const Eigen::VectorXd& x, Eigen::VectorXd& y);

// visit(r, c, block) for every 3x3 block (row block r, column block c) of a full symmetric
// Eigen matrix of dense 3x3 blocks, column block by column block, as an Eigen::Map onto its
// values (const for a const matrix): block column c holds its blocks at the same offset k
// (from the column's start) in each of its three columns; for a symmetric matrix they are
// row c's blocks, transposed
template <typename Matrix, typename Visit>
void for_each_block(Matrix& a, Visit&& visit) {
  using Block = std::conditional_t<std::is_const_v<Matrix>, const Mat3, Mat3>;
  const int* outer = a.outerIndexPtr();
  const int* inner = a.innerIndexPtr();
  auto* values = a.valuePtr();
  for (int c = 0; c < a.cols() / 3; ++c) {
    const int length = outer[3 * c + 1] - outer[3 * c];
    for (int k = 0; k < length; k += 3) {
      Eigen::Map<Block, 0, Eigen::OuterStride<>> block(values + outer[3 * c] + k, 3, 3, Eigen::OuterStride<>(length));
      visit(inner[outer[3 * c] + k] / 3, c, block);
    }
  }
}

// The block matrix of an Eigen matrix's pattern (full symmetric storage, dense 3x3 blocks),
// values zero, with the positions copy_values reads
BlockMatrix block_matrix(const Eigen::SparseMatrix<double>& pattern);
// m's values (and their single-precision copy) from a matrix of the pattern m was made from
void copy_values(const Eigen::SparseMatrix<double>& a, BlockMatrix& m);

class Preconditioner {
 public:
  virtual ~Preconditioner() = default;
  // new values of the system matrix (full symmetric storage, 3x3 blocks, the pattern the
  // preconditioner was built for)
  virtual void update(const Eigen::SparseMatrix<double>& a) = 0;
  // z = P^-1 r (r and z of the matrix's size; z is overwritten)
  virtual void apply(const Eigen::VectorXd& r, Eigen::VectorXd& z) const = 0;
  // the matrix of the last update(), in 3x3 blocks (what the conjugate gradients multiply by)
  virtual const BlockMatrix& matrix() const = 0;
  // a copy with its own scratch (Cloth copies share one until they solve)
  virtual std::unique_ptr<Preconditioner> clone() const = 0;
};

// z_b = A_bb^-1 r_b per vertex block b
class BlockJacobi final : public Preconditioner {
 public:
  void update(const Eigen::SparseMatrix<double>& a) override;
  void apply(const Eigen::VectorXd& r, Eigen::VectorXd& z) const override;
  const BlockMatrix& matrix() const override { return matrix_; }
  std::unique_ptr<Preconditioner> clone() const override { return std::make_unique<BlockJacobi>(*this); }

 private:
  BlockMatrix matrix_;                                          // the system (its pattern from the first update)
  std::vector<Mat3, Eigen::aligned_allocator<Mat3>> inverse_;  // (blocks) inverses of the diagonal blocks
};

// One level's prolongation: fine block i takes sum over its entries (coarse J, weight w) of
// w x the coarse value of J, the same weight for x, y and z (so rigid translations pass
// exactly between levels)
struct Prolongation {
  std::vector<int> start;        // (fine + 1)
  std::vector<int> coarse;       // (entries)
  std::vector<double> weight;    // (entries)
};

class Multigrid final : public Preconditioner {
 public:
  // The hierarchy from the system's pattern (full symmetric storage, dense 3x3 blocks) and
  // the graph of its vertices' mesh edges (neighbours of each block, either direction;
  // the aggregates follow it), and the value per block of the system's rigid translations
  // (sqrt(m) for the mass-scaled system, whose unknown is M^1/2 dv). Built once per cloth;
  // only values change afterwards.
  Multigrid(const Eigen::SparseMatrix<double>& pattern, const std::vector<std::vector<int>>& edges,
            const Eigen::VectorXd& scale);

  void update(const Eigen::SparseMatrix<double>& a) override;
  void apply(const Eigen::VectorXd& r, Eigen::VectorXd& z) const override;
  const BlockMatrix& matrix() const override { return matrix_[0]; }
  std::unique_ptr<Preconditioner> clone() const override { return std::make_unique<Multigrid>(*this); }

  int levels() const { return static_cast<int>(matrix_.size()); }
  // the finest level's smoother as its sweeps read it (multigrid.cpp, "The smoother"): the
  // system's lower triangle less the non-edge blocks the last update dropped, their norms
  // added to the diagonals
  const LowerBlocks& smoother() const { return smoother_.lower; }
  // rows of the last update whose smoother kept every block (their non-edge blocks would have
  // distorted them), and the non-edge blocks it dropped
  int smoother_full_rows() const;
  int smoother_dropped() const { return static_cast<int>(matrix_[0].lower.column.size() - smoother_.lower.column.size()); }
  int level_size(int l) const { return matrix_[l].size; }  // block rows of level l (0 finest)
  const BlockMatrix& level(int l) const { return matrix_[l]; }  // the operator of level l

 private:
  // A product's recipe: target[k] += weight[k] x source[from[k]] (3x3 blocks)
  struct Recipe {
    std::vector<int> from, to;
    std::vector<double> weight;
  };
  // The finest level's smoother (multigrid.cpp, "The smoother"): level 0's lower triangle
  // less the blocks between vertices that share no mesh edge (bending's, across hinges),
  // each dropped where neither of its rows would be distorted by more than
  // kMaxSmootherDistortion; their norms go to the diagonals. Its pattern is made anew each
  // update, from the values
  struct EdgeSmoother {
    LowerBlocks lower;                 // the kept blocks of each row, then its diagonal (compensated)
    std::vector<char> edge;            // (level 0's lower entries) 1 where the two vertices share an edge
    std::vector<char> keep_row;        // (blocks) scratch: the row keeps every block this update
    std::vector<double> hinge, added;  // (blocks) scratch: the norms of a row's non-edge blocks; of those dropped
    std::vector<double> norm;          // (level 0's lower entries) scratch: each non-edge block's norm
  };
  std::vector<BlockMatrix> matrix_;           // (levels) the operators, 0 finest
  EdgeSmoother smoother_;
  std::vector<Prolongation> prolongation_;    // (levels - 1) from level l + 1 to level l
  std::vector<BlockMatrix> product_;          // (levels - 1) scratch A_l P_l
  std::vector<Recipe> right_, left_;          // (levels - 1) A P from A, then P^T (A P)
  std::vector<std::vector<double>> inverse_diagonal_;  // per level (9 blocks + 1) D^-1, 9 a block column-major, and a pad
  Eigen::LLT<Eigen::MatrixXd> coarsest_;      // dense Cholesky of the coarsest level
  // V-cycle scratch per level: right-hand side and solution (from level 1), residual
  mutable std::vector<Eigen::VectorXd> rhs_, solution_, residual_;

  void update_smoother();
  // the patterns of a coarser level's products and the recipes that fill their blocks:
  // B = A P from A's blocks, then C = P^T B from B's (count coarse blocks)
  static void right_product(const BlockMatrix& a, const Prolongation& p, BlockMatrix& b, Recipe& right);
  static void left_product(const BlockMatrix& b, const Prolongation& p, int count, BlockMatrix& coarse, Recipe& left);
  // one V-cycle from `level` down: x = V b (level 0's b and x are apply's own vectors)
  void cycle(int level, const Eigen::VectorXd& b, Eigen::VectorXd& x) const;
};

}  // namespace simbake::cloth_detail
