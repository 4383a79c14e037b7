// Smoothed-aggregation algebraic multigrid as the cloth's conjugate-gradient preconditioner.
//
// Why. The implicit step solves A z = b with A = I + M^-1/2 (dt^2 H + c dt H_m) M^-1/2 (the
// system scaled by the lumped masses). Its spectrum runs from ~1 (motions the mass
// dominates: rigid ones, bending, in-plane waves longer than the distance sound travels in a
// step, sqrt(Y / rho) dt) up to 1 + dt^2 omega_max^2 with omega_max^2 ~
// 4 k / m ~ Y / (rho h^2): the condition number grows as 1/h^2, and block-Jacobi CG's
// iterations as 1/h, so that each doubling of the resolution costs 4 x 2 = 8x. A multigrid
// V-cycle removes the smooth, stiff in-plane error on coarse levels, where it is not smooth,
// so that the count of iterations stays nearly flat and each costs O(n).
//
// Which. Block-Jacobi's iterations per step double with each doubling of the resolution;
// this preconditioner's stay nearly flat, each a few times dearer, so it wins from about a
// thousand vertices on. It is algebraic so that it works for any triangle mesh (mesh cloths,
// pins, holes): the levels are built from the mesh's edge graph, never from a grid. (A
// geometric multigrid would only serve grids; an incomplete or lagged Cholesky factorization
// still needs O(1/h) iterations, or a fill that grows with n; a direct factorization each
// step costs many times block-Jacobi CG.)
//
// Method (Vanek, Mandel and Brezina 1996, "Algebraic multigrid by smoothed aggregation for
// second and fourth order elliptic problems"; Trottenberg, Oosterlee and Schuller 2001,
// "Multigrid", appendix A on AMG):
//  * Aggregates (built once, from the graph): a vertex whose neighbours are all free starts
//    an aggregate with them (pass 1, in index order); a vertex left over joins the aggregate
//    of its first aggregated neighbour (pass 2); what is still left forms aggregates with its
//    free neighbours (pass 3). On a grid with diagonals an aggregate is a vertex and its six
//    neighbours, so each level has ~1/5-1/7 of the blocks of the one below.
//  * Tentative prolongation: T(i, J) = 1 when vertex i is in aggregate J, the same for x, y
//    and z, so that it reproduces the rigid translations (the stiffness's null space).
//    On the finest level the unknown is M^1/2 dv, where a translation is sqrt(m_i) x a
//    constant: P's rows there are scaled by sqrt(m_i) (at a grid's edges and corners the
//    masses are a half and a quarter; unscaled, a free fall's uniform dv is no longer a
//    coarse translation and takes about twice the iterations). Rotations are not in the
//    coarse space (it would need 6 unknowns per aggregate); smooth hats approximate them,
//    and the iteration count grows slowly with the resolution.
//  * Smoothed prolongation: P = (I - w D^-1 L) T, w = 2/3, with L = D - W the graph
//    Laplacian of the level's edge graph (D the degrees). Its rows still sum to 1 (L 1 = 0),
//    so translations pass exactly; each coarse basis function is a smooth hat over its
//    aggregate and its neighbours, which makes the coarse space approximate smooth fields
//    to first order (what the stiff in-plane error is), instead of the piecewise constants
//    of unsmoothed aggregation (whose coarse operators are too stiff: its V-cycle needs
//    more iterations as the mesh is refined). The classical choice smooths with A itself;
//    the graph Laplacian keeps P independent of the values, so that the hierarchy, P and
//    the patterns of the coarse operators are built once per cloth.
//  * Galerkin coarse operators A_(l+1) = P^T A_l P (x I3), recomputed every step since A's
//    values change, by two precomputed recipes over 3x3 blocks: B = A P, then P^T B. That
//    costs a few fine matrix-vector products. The next level's graph joins two
//    aggregates when a mesh edge joins them.
//  * Levels stop at <= 48 blocks (or when a level does not shrink by 1/5); the coarsest
//    level is solved by a dense Cholesky factorization (each step).
//  * The V-cycle: a forward block Gauss-Seidel sweep from zero (3x3 diagonal blocks solved
//    exactly), the residual restricted by P^T, the coarse correction, then a backward sweep:
//        x = S_fwd(b);  x += P V_(l+1)(P^T (b - A x));  x = S_bwd(b, x).
//    The backward sweep is the forward one's adjoint, so the cycle is a symmetric positive
//    definite operator: a valid CG preconditioner. The sweeps read the off-diagonal blocks
//    of the lower triangle only, in single precision (the products are summed in double;
//    both sweeps read the same rounded matrix, so the cycle stays symmetric): the cycle is
//    bound by memory traffic, and its rounding (1e-7 relative) is far below what a
//    preconditioner may err. Each sweep reads a row's blocks once for two uses: the
//    forward sweep gathers A_ij x_j (j < i) to solve row i, then scatters -A_ij^T x_i
//    into the residual of the rows j (the residual of a forward sweep from zero is the
//    upper triangle's product alone), and the backward sweep gathers the old x_j (j < i)
//    and scatters the new x_i to the rows it precedes. Against full storage, with the
//    sweeps and the residual each walking their rows, this reads 2 x 6 instead of 30 of a
//    grid's 13 blocks a row per cycle at the finest level (2 x 3 with the smoother below).
//  * The smoother. On the finest level the sweeps read the blocks between mesh-edge
//    neighbours, 3 of the 6 below the diagonal in a grid's row, and drop the other 3 where
//    they are small. Those couple the two vertices across a hinge, through bending alone,
//    orders of magnitude below a spring's block and the diagonal. Each dropped block's norm
//    is added to the diagonals of its row and its column (diagonal compensation), so that
//    the smoother's matrix S satisfies u . S u >= u . A u (each dropped pair's part of
//    S - A is [|E| I, -E; -E^T, |E| I], positive semi-definite): its Gauss-Seidel
//    converges, and the cycle stays symmetric positive definite (the restriction takes S's
//    residual, the coarse levels are Galerkin's of A). The conjugate gradients multiply by
//    A itself, so the solve still meets its tolerance on the true system. The compensation
//    makes S stiffer than A, most where bending is a large part of a diagonal's smallest
//    eigenvalue (the out-of-plane one): its share there, (sum |E|) |D^-1|, grows as the mesh
//    is refined (the bending blocks grow as 1/h^2 against the diagonal). A row whose share
//    would pass 0.5 keeps its blocks (every update decides, from the values): dropped
//    everywhere, the stiffer smoother costs more iterations than the blocks it saves;
//    dropped without any compensation, the cycle is no longer a convergent smoother and the
//    iterations nearly double. Reading half the blocks makes the cycle, the bulk of the
//    solve, correspondingly cheaper at the same iteration count.
//    Everything runs in a fixed order on one thread, so the result has the same bits at any
//    thread count.
#include "cloth/multigrid.h"

#include "cloth/lower_kernels.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace simbake::cloth_detail {

namespace {

constexpr int kCoarsestBlocks = 48;          // solve directly at or below this many blocks
constexpr int kMaxLevels = 16;
constexpr double kSmoothingWeight = 2.0 / 3.0;  // w of P = (I - w D^-1 L) T
constexpr double kLeastShrink = 0.8;         // stop when a level keeps more than this share
// the finest smoother drops a non-edge block only where no row's diagonal grows by more than
// this share of its smallest eigenvalue (see "The smoother")
constexpr double kMaxSmootherDistortion = 0.5;

using Graph = std::vector<std::vector<int>>;  // (blocks) sorted neighbours, no self

Eigen::Map<const Vec3> at(const Eigen::VectorXd& v, int b) { return Eigen::Map<const Vec3>(v.data() + 3 * b); }
Eigen::Map<Vec3> at(Eigen::VectorXd& v, int b) { return Eigen::Map<Vec3>(v.data() + 3 * b); }

// Aggregates of a graph (see the top of this file); returns each vertex's aggregate and
// their count
std::vector<int> aggregate(const Graph& graph, int& count) {
  const int n = static_cast<int>(graph.size());
  std::vector<int> owner(n, -1);
  count = 0;
  // pass 1: a vertex and its neighbours, all free, make an aggregate
  for (int i = 0; i < n; ++i) {
    if (owner[i] >= 0) continue;
    bool free = true;
    for (int j : graph[i]) free = free && owner[j] < 0;
    if (!free) continue;
    owner[i] = count;
    for (int j : graph[i]) owner[j] = count;
    ++count;
  }
  // pass 2: leftovers join their first aggregated neighbour's aggregate (of pass 1)
  std::vector<int> first = owner;
  for (int i = 0; i < n; ++i) {
    if (owner[i] >= 0) continue;
    for (int j : graph[i]) {
      if (first[j] >= 0) {
        owner[i] = first[j];
        break;
      }
    }
  }
  // pass 3: what is left (only where pass 2 found no neighbour) with its free neighbours
  for (int i = 0; i < n; ++i) {
    if (owner[i] >= 0) continue;
    owner[i] = count;
    for (int j : graph[i]) {
      if (owner[j] < 0) owner[j] = count;
    }
    ++count;
  }
  return owner;
}

// P = (I - w D^-1 L) T for the aggregates `owner` of `graph`:
// P(i, J) = (1 - w) [owner(i) = J] + w / deg(i) #{j ~ i : owner(j) = J}
Prolongation smoothed_prolongation(const Graph& graph, const std::vector<int>& owner) {
  const int n = static_cast<int>(graph.size());
  Prolongation p;
  p.start.assign(1, 0);
  std::vector<std::pair<int, double>> row;
  for (int i = 0; i < n; ++i) {
    row.clear();
    const double degree = static_cast<double>(graph[i].size());
    row.emplace_back(owner[i], degree > 0.0 ? 1.0 - kSmoothingWeight : 1.0);
    for (int j : graph[i]) row.emplace_back(owner[j], kSmoothingWeight / degree);
    std::sort(row.begin(), row.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    // merge equal columns (a fixed order of additions: deterministic)
    for (size_t k = 0; k < row.size(); ++k) {
      if (k > 0 && row[k].first == p.coarse.back() && static_cast<int>(p.coarse.size()) > p.start.back()) {
        p.weight.back() += row[k].second;
      } else {
        p.coarse.push_back(row[k].first);
        p.weight.push_back(row[k].second);
      }
    }
    p.start.push_back(static_cast<int>(p.coarse.size()));
  }
  return p;
}

// The next level's graph: aggregates joined by an edge of this level's graph
Graph coarse_graph(const Graph& graph, const std::vector<int>& owner, int count) {
  Graph coarse(count);
  for (size_t i = 0; i < graph.size(); ++i) {
    for (int j : graph[i]) {
      if (owner[i] != owner[j]) coarse[owner[i]].push_back(owner[j]);
    }
  }
  for (std::vector<int>& row : coarse) {
    std::sort(row.begin(), row.end());
    row.erase(std::unique(row.begin(), row.end()), row.end());
  }
  return coarse;
}

// A block matrix with the given rows' sorted columns (values zero)
BlockMatrix block_pattern(const std::vector<std::vector<int>>& rows) {
  BlockMatrix m;
  m.size = static_cast<int>(rows.size());
  m.start.assign(1, 0);
  for (int i = 0; i < m.size; ++i) {
    for (int j : rows[i]) {
      if (j == i) m.diagonal.push_back(static_cast<int>(m.column.size()));
      m.column.push_back(j);
    }
    if (static_cast<int>(m.diagonal.size()) != i + 1) throw std::logic_error("multigrid: a block row has no diagonal");
    m.start.push_back(static_cast<int>(m.column.size()));
  }
  m.block.assign(m.column.size(), Mat3::Zero());
  // the lower triangle's pattern: each row's entries before its diagonal, then the diagonal
  LowerBlocks& lower = m.lower;
  lower.start.assign(1, 0);
  for (int i = 0; i < m.size; ++i) {
    for (int k = m.start[i]; k <= m.diagonal[i]; ++k) {
      lower.column.push_back(m.column[k]);
      lower.source.push_back(k);
    }
    lower.start.push_back(static_cast<int>(lower.column.size()));
  }
  lower.block.assign(9 * lower.column.size() + 1, 0.0f);
  return m;
}

// the entry of (i, j) in m (it must exist)
int entry(const BlockMatrix& m, int i, int j) {
  const int* begin = m.column.data() + m.start[i];
  const int* end = m.column.data() + m.start[i + 1];
  return static_cast<int>(std::lower_bound(begin, end, j) - m.column.data());
}

// inverses of the diagonal blocks (a zero block, of a vertex with no mass, stays zero)
void invert_diagonal(const BlockMatrix& m, std::vector<Mat3, Eigen::aligned_allocator<Mat3>>& inverse) {
  inverse.resize(m.size);
  for (int i = 0; i < m.size; ++i) inverse[i] = m.block[m.diagonal[i]].inverse();
}

// the same, 9 doubles a block column-major and a pad (what the sweeps read, lower_kernels.h)
void invert_diagonal(const BlockMatrix& m, std::vector<double>& inverse) {
  inverse.assign(9 * m.size + 1, 0.0);
  for (int i = 0; i < m.size; ++i) Eigen::Map<Mat3>(inverse.data() + 9 * i) = m.block[m.diagonal[i]].inverse();
}

}  // namespace

// ---- block matrices

BlockMatrix block_matrix(const Eigen::SparseMatrix<double>& pattern) {
  std::vector<std::vector<int>> rows(pattern.cols() / 3);
  std::vector<int> source, stride;
  for_each_block(pattern, [&](int r, int c, const auto& block) {
    rows[c].push_back(r);
    source.push_back(static_cast<int>(block.data() - pattern.valuePtr()));
    stride.push_back(static_cast<int>(block.outerStride()));
  });
  BlockMatrix m = block_pattern(rows);
  m.source = std::move(source);
  m.stride = std::move(stride);
  return m;
}

namespace {

// m.lower's values from m.block
void single_precision(BlockMatrix& m) {
  LowerBlocks& lower = m.lower;
  for (size_t k = 0; k < lower.source.size(); ++k) {
    const double* from = m.block[lower.source[k]].data();
    for (int e = 0; e < 9; ++e) lower.block[9 * k + e] = static_cast<float>(from[e]);
  }
}

LowerView lower_view(int size, const LowerBlocks& lower) {
  return {size, lower.start.data(), lower.column.data(), lower.block.data()};
}

LowerView lower_view(const BlockMatrix& a) { return lower_view(a.size, a.lower); }

}  // namespace

void copy_values(const Eigen::SparseMatrix<double>& a, BlockMatrix& m) {
  const double* values = a.valuePtr();
  for (size_t k = 0; k < m.block.size(); ++k) {
    const double* v = values + m.source[k];
    const int s = m.stride[k];
    Mat3& block = m.block[k];
    for (int c = 0; c < 3; ++c) {
      for (int r = 0; r < 3; ++r) block(c, r) = v[c * s + r];
    }
  }
  single_precision(m);
}

double lower_product(const BlockMatrix& a, const Eigen::VectorXd& x, Eigen::VectorXd& y) {
  y.resize(3 * a.size);
  return lower_product(lower_view(a), x.data(), y.data());
}

// ---- block-Jacobi

void BlockJacobi::update(const Eigen::SparseMatrix<double>& a) {
  if (matrix_.size != a.cols() / 3 || matrix_.block.size() * 9 != static_cast<size_t>(a.nonZeros())) {
    matrix_ = block_matrix(a);
  }
  copy_values(a, matrix_);
  invert_diagonal(matrix_, inverse_);
}

void BlockJacobi::apply(const Eigen::VectorXd& r, Eigen::VectorXd& z) const {
  z.resize(r.size());
  for (size_t k = 0; k < inverse_.size(); ++k) at(z, static_cast<int>(k)) = inverse_[k] * at(r, static_cast<int>(k));
}

// B = A P: its pattern (fine rows, coarse columns) and the recipe of its blocks from A's
void Multigrid::right_product(const BlockMatrix& a, const Prolongation& p, BlockMatrix& b, Recipe& right) {
  std::vector<std::vector<int>> b_rows(a.size);
  for (int i = 0; i < a.size; ++i) {
    for (int k = a.start[i]; k < a.start[i + 1]; ++k) {
      const int j = a.column[k];
      for (int e = p.start[j]; e < p.start[j + 1]; ++e) b_rows[i].push_back(p.coarse[e]);
    }
    std::sort(b_rows[i].begin(), b_rows[i].end());
    b_rows[i].erase(std::unique(b_rows[i].begin(), b_rows[i].end()), b_rows[i].end());
  }
  b.size = a.size;
  b.start.assign(1, 0);
  for (const std::vector<int>& row : b_rows) {
    b.column.insert(b.column.end(), row.begin(), row.end());
    b.start.push_back(static_cast<int>(b.column.size()));
  }
  b.block.assign(b.column.size(), Mat3::Zero());
  for (int i = 0; i < a.size; ++i) {
    for (int k = a.start[i]; k < a.start[i + 1]; ++k) {
      const int j = a.column[k];
      for (int e = p.start[j]; e < p.start[j + 1]; ++e) {
        right.from.push_back(k);
        right.to.push_back(entry(b, i, p.coarse[e]));
        right.weight.push_back(p.weight[e]);
      }
    }
  }
}

// C = P^T B: its pattern (coarse x coarse, each row with its diagonal) and the recipe of its
// blocks from B's
void Multigrid::left_product(const BlockMatrix& b, const Prolongation& p, int count, BlockMatrix& coarse, Recipe& left) {
  const int fine = b.size;
  std::vector<std::vector<int>> c_rows(count);
  for (int i = 0; i < fine; ++i) {
    for (int e = p.start[i]; e < p.start[i + 1]; ++e) {
      std::vector<int>& row = c_rows[p.coarse[e]];
      row.insert(row.end(), b.column.begin() + b.start[i], b.column.begin() + b.start[i + 1]);
    }
  }
  for (int c = 0; c < count; ++c) {
    std::vector<int>& row = c_rows[c];
    row.push_back(c);  // a coarse block always has its diagonal
    std::sort(row.begin(), row.end());
    row.erase(std::unique(row.begin(), row.end()), row.end());
  }
  coarse = block_pattern(c_rows);
  for (int i = 0; i < fine; ++i) {
    for (int e = p.start[i]; e < p.start[i + 1]; ++e) {
      for (int k = b.start[i]; k < b.start[i + 1]; ++k) {
        left.from.push_back(k);
        left.to.push_back(entry(coarse, p.coarse[e], b.column[k]));
        left.weight.push_back(p.weight[e]);
      }
    }
  }
}

// ---- multigrid: the hierarchy (once per cloth)

Multigrid::Multigrid(const Eigen::SparseMatrix<double>& pattern, const std::vector<std::vector<int>>& edges,
                     const Eigen::VectorXd& scale) {
  const int n = static_cast<int>(pattern.cols() / 3);
  if (static_cast<int>(edges.size()) != n || scale.size() != n) throw std::invalid_argument("multigrid: one edge list and scale per block");
  matrix_.push_back(block_matrix(pattern));
  Graph graph = edges;
  for (std::vector<int>& row : graph) {
    std::sort(row.begin(), row.end());
    row.erase(std::unique(row.begin(), row.end()), row.end());
  }

  // which of level 0's lower blocks lie between mesh-edge neighbours (the smoother's)
  {
    const LowerBlocks& lower = matrix_[0].lower;
    smoother_.edge.assign(lower.column.size(), 0);
    for (int i = 0; i < n; ++i) {
      for (int k = lower.start[i]; k + 1 < lower.start[i + 1]; ++k) {
        smoother_.edge[k] = std::binary_search(graph[i].begin(), graph[i].end(), lower.column[k]) ? 1 : 0;
      }
    }
  }
  // coarser levels while they pay
  while (matrix_.back().size > kCoarsestBlocks && static_cast<int>(matrix_.size()) < kMaxLevels) {
    const BlockMatrix& a = matrix_.back();
    int count = 0;
    const std::vector<int> owner = aggregate(graph, count);
    if (count > kLeastShrink * a.size) break;
    Prolongation p = smoothed_prolongation(graph, owner);
    // level 0: the translations of the scaled system are s_i x constant
    if (matrix_.size() == 1) {
      for (int i = 0; i < a.size; ++i) {
        for (int e = p.start[i]; e < p.start[i + 1]; ++e) p.weight[e] *= scale[i];
      }
    }
    BlockMatrix b, coarse;
    Recipe right, left;
    right_product(a, p, b, right);
    left_product(b, p, count, coarse, left);
    graph = coarse_graph(graph, owner, count);
    prolongation_.push_back(std::move(p));
    product_.push_back(std::move(b));
    right_.push_back(std::move(right));
    left_.push_back(std::move(left));
    matrix_.push_back(std::move(coarse));
  }
  inverse_diagonal_.resize(matrix_.size());
  rhs_.resize(matrix_.size());
  solution_.resize(matrix_.size());
  residual_.resize(matrix_.size());
  for (size_t l = 0; l < matrix_.size(); ++l) {
    if (l > 0) {  // level 0's are apply's vectors
      rhs_[l].setZero(3 * matrix_[l].size);
      solution_[l].setZero(3 * matrix_[l].size);
    }
    residual_[l].setZero(3 * matrix_[l].size);
  }
}

// ---- multigrid: the values (every step)

void Multigrid::update(const Eigen::SparseMatrix<double>& a) {
  copy_values(a, matrix_[0]);
  // Galerkin products level by level: B = A P, then A_(l+1) = P^T B
  for (size_t l = 0; l + 1 < matrix_.size(); ++l) {
    BlockMatrix& b = product_[l];
    std::fill(b.block.begin(), b.block.end(), Mat3::Zero());
    const Recipe& right = right_[l];
    for (size_t k = 0; k < right.from.size(); ++k) b.block[right.to[k]] += right.weight[k] * matrix_[l].block[right.from[k]];
    BlockMatrix& coarse = matrix_[l + 1];
    std::fill(coarse.block.begin(), coarse.block.end(), Mat3::Zero());
    const Recipe& left = left_[l];
    for (size_t k = 0; k < left.from.size(); ++k) coarse.block[left.to[k]] += left.weight[k] * b.block[left.from[k]];
  }
  update_smoother();
  for (size_t l = 1; l + 1 < matrix_.size(); ++l) {
    invert_diagonal(matrix_[l], inverse_diagonal_[l]);
    single_precision(matrix_[l]);  // level 0's by copy_values
  }
  // the coarsest level, dense
  const BlockMatrix& last = matrix_.back();
  Eigen::MatrixXd dense = Eigen::MatrixXd::Zero(3 * last.size, 3 * last.size);
  for (int i = 0; i < last.size; ++i) {
    for (int k = last.start[i]; k < last.start[i + 1]; ++k) dense.block<3, 3>(3 * i, 3 * last.column[k]) = last.block[k];
  }
  coarsest_.compute(dense);
}

// The finest level's smoother from level 0's values ("The smoother" above). A row i would
// be distorted by dropping its non-edge blocks E_ij by about (sum_j |E_ij|) |D_i^-1| (the
// diagonal's growth against its smallest eigenvalue; Frobenius norms, each >= the spectral
// one): a block is dropped, and its norm added to the diagonals of its row and its column,
// only where neither row would be distorted by more than kMaxSmootherDistortion; else kept.
// Then the inverses of the compensated diagonals.
void Multigrid::update_smoother() {
  const BlockMatrix& a = matrix_[0];
  const LowerBlocks& full = a.lower;
  EdgeSmoother& s = smoother_;
  s.hinge.assign(a.size, 0.0);
  s.added.assign(a.size, 0.0);
  s.keep_row.resize(a.size);
  s.norm.resize(full.column.size());
  for (int i = 0; i < a.size; ++i) {
    for (int k = full.start[i]; k + 1 < full.start[i + 1]; ++k) {
      if (s.edge[k]) continue;
      const double e = s.norm[k] = a.block[full.source[k]].norm();
      s.hinge[i] += e;
      s.hinge[full.column[k]] += e;
    }
  }
  for (int i = 0; i < a.size; ++i) {
    s.keep_row[i] = s.hinge[i] * a.block[a.diagonal[i]].inverse().norm() > kMaxSmootherDistortion;
  }
  LowerBlocks& lower = s.lower;
  lower.start.assign(1, 0);
  lower.column.clear();
  lower.block.clear();
  for (int i = 0; i < a.size; ++i) {
    for (int k = full.start[i]; k + 1 < full.start[i + 1]; ++k) {
      const int j = full.column[k];
      if (s.edge[k] || s.keep_row[i] || s.keep_row[j]) {
        lower.column.push_back(j);
        lower.block.insert(lower.block.end(), full.block.begin() + 9 * k, full.block.begin() + 9 * k + 9);
      } else {
        s.added[i] += s.norm[k];
        s.added[j] += s.norm[k];
      }
    }
    lower.column.push_back(i);
    lower.block.resize(lower.block.size() + 9);  // the diagonal, below
    lower.start.push_back(static_cast<int>(lower.column.size()));
  }
  lower.block.push_back(0.0f);  // the pad the kernels read past the last block
  std::vector<double>& inverse = inverse_diagonal_[0];
  inverse.assign(9 * a.size + 1, 0.0);
  for (int i = 0; i < a.size; ++i) {
    const Mat3 d = a.block[a.diagonal[i]] + s.added[i] * Mat3::Identity();
    float* slot = lower.block.data() + 9 * (lower.start[i + 1] - 1);
    for (int e = 0; e < 9; ++e) slot[e] = static_cast<float>(d.data()[e]);
    Eigen::Map<Mat3>(inverse.data() + 9 * i) = d.inverse();
  }
}

int Multigrid::smoother_full_rows() const {
  return static_cast<int>(std::count(smoother_.keep_row.begin(), smoother_.keep_row.end(), 1));
}

// ---- multigrid: the V-cycle

void Multigrid::apply(const Eigen::VectorXd& r, Eigen::VectorXd& z) const {
  z.resize(r.size());
  cycle(0, r, z);
}

void Multigrid::cycle(int level, const Eigen::VectorXd& b, Eigen::VectorXd& x) const {
  const BlockMatrix& a = matrix_[level];
  if (level + 1 == static_cast<int>(matrix_.size())) {
    x = coarsest_.solve(b);
    return;
  }
  const double* inverse = inverse_diagonal_[level].data();
  const LowerView lower = level == 0 ? lower_view(a.size, smoother_.lower) : lower_view(a);
  // forward Gauss-Seidel from zero, x_i = A_ii^-1 (b_i - sum_(j < i) A_ij x_j), fused with
  // the residual b - A x: each row's sweep leaves b_i - sum_(j <= i) A_ij x_j = 0, so the
  // residual is -sum_(j > i) A_ij x_j, which row j's blocks scatter, transposed, once x_j is known
  Eigen::VectorXd& res = residual_[level];
  forward_sweep(lower, inverse, b.data(), x.data(), res.data());
  // restrict it: b_c = P^T (b - A x)
  const Prolongation& p = prolongation_[level];
  Eigen::VectorXd& coarse_rhs = rhs_[level + 1];
  coarse_rhs.setZero();
  for (int i = 0; i < a.size; ++i) {
    for (int e = p.start[i]; e < p.start[i + 1]; ++e) at(coarse_rhs, p.coarse[e]) += p.weight[e] * at(res, i);
  }
  // coarse correction: x += P x_c
  cycle(level + 1, coarse_rhs, solution_[level + 1]);
  const Eigen::VectorXd& coarse_x = solution_[level + 1];
  for (int i = 0; i < a.size; ++i) {
    Vec3 s = Vec3::Zero();
    for (int e = p.start[i]; e < p.start[i + 1]; ++e) s += p.weight[e] * at(coarse_x, p.coarse[e]);
    at(x, i) += s;
  }
  // backward Gauss-Seidel, x_i = A_ii^-1 (b_i - sum_(j < i) A_ij x_j - sum_(j > i) A_ij x_j)
  // for i from the last: the rows before i still hold their old values, which row i's
  // blocks read; the rows after i are new, and their part was scattered, transposed, into a
  // scratch vector as each was done
  backward_sweep(lower, inverse, b.data(), x.data(), res.data());
}

}  // namespace simbake::cloth_detail
