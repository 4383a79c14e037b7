// The block LU against Eigen's dense LU on the same matrices (trees, a chain, loops, blocks
// of mixed sizes, non-symmetric values), and the fill it makes: none for a tree.
#include <gtest/gtest.h>

#include "math/block_sparse_lu.h"

#include <Eigen/Dense>

#include <random>

using namespace simbake;

namespace {

// Fills every block of the pattern with random values, the diagonal blocks made dominant
// (a well-posed system, not symmetric), and returns the same matrix dense
Eigen::MatrixXd fill_random(BlockSparseLU& lu, const std::vector<std::pair<int, int>>& adjacent, std::mt19937& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const int n = lu.size();
  Eigen::MatrixXd dense = Eigen::MatrixXd::Zero(n, n);
  lu.set_zero();
  const auto put = [&](int a, int b, double scale) {
    double* block = lu.block(a, b);
    ASSERT_NE(block, nullptr);
    for (int r = 0; r < lu.node_size(a); ++r) {
      for (int c = 0; c < lu.node_size(b); ++c) {
        const double value = scale * u(rng) + (a == b && r == c ? 4.0 * lu.node_size(a) : 0.0);
        block[r * lu.node_size(b) + c] = value;
        dense(lu.offset(a) + r, lu.offset(b) + c) = value;
      }
    }
  };
  for (int k = 0; k < lu.node_count(); ++k) put(k, k, 1.0);
  for (const auto& [a, b] : adjacent) {
    put(a, b, 1.0);
    put(b, a, 1.0);
  }
  return dense;
}

double solve_error(const std::vector<int>& sizes, const std::vector<std::pair<int, int>>& adjacent, int seed,
                   int* fill = nullptr) {
  std::mt19937 rng(seed);
  BlockSparseLU lu;
  lu.analyze(sizes, adjacent);
  const Eigen::MatrixXd dense = fill_random(lu, adjacent, rng);
  const Eigen::VectorXd b = Eigen::VectorXd::Random(lu.size());
  const Eigen::VectorXd expected = dense.partialPivLu().solve(b);
  EXPECT_TRUE(lu.factorize());
  Eigen::VectorXd x = b;
  lu.solve(x.data());
  if (fill) *fill = lu.fill_blocks();
  return (x - expected).norm() / expected.norm();
}

}  // namespace

// A chain of 50 three-row nodes (a chain of ball joints): the dense solve's answer, no fill
TEST(BlockSparseLU, ChainMatchesDenseWithNoFill) {
  std::vector<int> sizes(50, 3);
  std::vector<std::pair<int, int>> adjacent;
  for (int k = 1; k < 50; ++k) adjacent.push_back({k - 1, k});
  int fill = -1;
  EXPECT_LT(solve_error(sizes, adjacent, 1, &fill), 1e-12);
  EXPECT_EQ(fill, 0);
}

// A ragdoll-like tree of joints with mixed sizes: joints on one body form a clique (they all
// share it); eliminated leaves first, nothing fills in
TEST(BlockSparseLU, TreeOfCliquesMatchesDenseWithNoFill) {
  // bodies: pelvis 0 with joints 0 (spine), 1, 2 (hips); spine body with 0, 3 (neck), 4, 5
  // (shoulders); legs 1-6, 2-7; arms 4-8, 5-9
  const std::vector<int> sizes = {6, 8, 8, 5, 6, 6, 7, 7, 4, 4};
  const std::vector<std::vector<int>> bodies = {{0, 1, 2}, {0, 3, 4, 5}, {1, 6}, {2, 7}, {4, 8}, {5, 9}};
  std::vector<std::pair<int, int>> adjacent;
  for (const auto& joints : bodies) {
    for (std::size_t a = 0; a < joints.size(); ++a) {
      for (std::size_t b = a + 1; b < joints.size(); ++b) adjacent.push_back({joints[a], joints[b]});
    }
  }
  for (int seed = 0; seed < 5; ++seed) {
    int fill = -1;
    EXPECT_LT(solve_error(sizes, adjacent, seed, &fill), 1e-12) << "seed " << seed;
    EXPECT_EQ(fill, 0);
  }
}

// Loops (a grid of glued pieces): fill is made, the answer is still the dense one
TEST(BlockSparseLU, LoopsFillInAndMatchDense) {
  const int w = 6, h = 5;
  std::vector<int> sizes(w * h);
  for (int k = 0; k < w * h; ++k) sizes[k] = 1 + k % 6;
  std::vector<std::pair<int, int>> adjacent;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      if (x + 1 < w) adjacent.push_back({y * w + x, y * w + x + 1});
      if (y + 1 < h) adjacent.push_back({y * w + x, (y + 1) * w + x});
    }
  }
  int fill = -1;
  EXPECT_LT(solve_error(sizes, adjacent, 7, &fill), 1e-11);
  EXPECT_GT(fill, 0);
}

// A singular pivot is reported, not divided by
TEST(BlockSparseLU, SingularPivotIsReported) {
  BlockSparseLU lu;
  lu.analyze({2}, {});
  lu.set_zero();
  double* d = lu.block(0, 0);
  d[0] = 1.0;
  d[1] = 2.0;
  d[2] = 2.0;
  d[3] = 4.0;
  EXPECT_FALSE(lu.factorize());
}
