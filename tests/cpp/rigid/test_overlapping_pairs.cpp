// The broad phase's grid against the definition: every pair of overlapping boxes, once, sorted.
#include <gtest/gtest.h>

#include "rigid/overlapping_pairs.h"

#include <random>

using namespace simbake;

namespace {

std::vector<std::pair<int, int>> brute_force(const std::vector<Box3>& boxes) {
  std::vector<std::pair<int, int>> pairs;
  for (int i = 0; i < static_cast<int>(boxes.size()); ++i)
    for (int j = i + 1; j < static_cast<int>(boxes.size()); ++j)
      if (boxes[i].intersects(boxes[j])) pairs.emplace_back(i, j);
  return pairs;
}

}  // namespace

TEST(OverlappingPairs, MatchesEveryPairTestedDirectly) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> where(-5.0, 5.0), size(0.2, 1.0);
  std::vector<Box3> boxes;
  for (int i = 0; i < 400; ++i) {
    const Vec3 lo(where(rng), where(rng), where(rng));
    boxes.emplace_back(lo, lo + Vec3(size(rng), size(rng), size(rng)));
  }
  boxes.emplace_back(Vec3(-6.0, -0.1, -6.0), Vec3(6.0, 0.1, 6.0));  // a platform over many cells
  boxes.emplace_back(Vec3(-4.0, -4.0, -4.0), Vec3(-3.5, -3.5, -3.5));
  GridScratch grid;
  std::vector<std::pair<int, int>> pairs;
  overlapping_pairs(boxes, grid, pairs);
  EXPECT_EQ(pairs, brute_force(boxes));
  // again with the scratch grown: the same answer
  overlapping_pairs(boxes, grid, pairs);
  EXPECT_EQ(pairs, brute_force(boxes));
}

TEST(OverlappingPairs, NoBoxesNoPairs) {
  GridScratch grid;
  std::vector<std::pair<int, int>> pairs{{0, 1}};
  overlapping_pairs({}, grid, pairs);
  EXPECT_TRUE(pairs.empty());
}
