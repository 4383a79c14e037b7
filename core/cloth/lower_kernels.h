// The arithmetic over the lower triangle of a symmetric 3x3-block matrix held in single
// precision (multigrid.h's LowerBlocks): the product the conjugate gradients multiply by and
// the two Gauss-Seidel sweeps of the multigrid V-cycle. These loops are where the implicit
// cloth step spends most of its time.
//
// Each block A_ij (j < i) is read once and used twice, for its row (A_ij x_j) and,
// transposed, for its column (A_ij^T x_i); its floats are converted to double and every sum is
// in double, in one fixed order:
//     (A x)_r = (a_r0 x_0 + a_r1 x_1) + a_r2 x_2      (row r of a block times a vector)
// Two builds of the same arithmetic: plain C++, and AVX2 (four doubles a register, the three
// rows of a block side by side; no fused multiply-add, which would round differently). Each
// operation is the same IEEE operation on the same operands in the same order, so both give
// the same bits (LowerKernels.AvxAndPlainGiveTheSameBits); the AVX2 build is used where the
// processor has it.
// Private to core/cloth.
#pragma once

namespace simbake::cloth_detail {

// A lower triangle as the kernels read it: block row i holds its blocks j < i, ascending, then
// its diagonal block last, at entries [start[i], start[i + 1]); each block is 9 floats,
// column-major, and the array holds one float more than its blocks (the AVX2 build reads
// four floats from each column's start)
struct LowerView {
  int size = 0;                  // block rows
  const int* start = nullptr;    // (size + 1)
  const int* column = nullptr;   // (entries)
  const float* block = nullptr;  // (9 entries + 1)
};

// y = A x (x, y of 3 size doubles; y is overwritten); returns x . A x
double lower_product(const LowerView& a, const double* x, double* y);

// Forward Gauss-Seidel from zero, x_i = D_i^-1 (b_i - sum_(j < i) A_ij x_j) for i ascending,
// with the residual it leaves: res = b - A x = -(sum_(j > i) A_ij x_j). inverse holds each
// row's D_i^-1, 9 doubles column-major, and one double more at the end
void forward_sweep(const LowerView& a, const double* inverse, const double* b, double* x, double* res);

// Backward Gauss-Seidel from x, x_i = D_i^-1 (b_i - sum_(j != i) A_ij x_j) for i descending
// (the rows after i already new); ahead is scratch of x's size
void backward_sweep(const LowerView& a, const double* inverse, const double* b, double* x, double* ahead);

// Whether the AVX2 build is used; tests turn it off to compare the two (returns the old value)
bool use_avx2(bool on);
bool avx2_available();

}  // namespace simbake::cloth_detail
