// Islands of an impulse stage: linked dynamic bodies share an island, the ground and
// kinematic bodies link nothing, items keep their order within an island.
#include <gtest/gtest.h>

#include "rigid/islands.h"

using namespace simbake;

namespace {

std::vector<RigidBodyDef> bodies(int n, std::vector<int> kinematic = {}) {
  std::vector<RigidBodyDef> defs(n);
  for (int i : kinematic) defs[i].kinematic = true;
  return defs;
}

}  // namespace

TEST(Islands, ChainsJoinAndTheGroundDoesNot) {
  // 0-1, 1-2 a chain; 3 and 4 each on the ground only; item 4 in no island
  IslandScratch islands;
  islands.links = {{0, 1}, {3, -1}, {1, 2}, {4, -1}, {-1, -1}};
  find_islands(bodies(5), islands);
  ASSERT_EQ(islands.count, 3);
  EXPECT_EQ(islands.of_item[0], islands.of_item[2]);
  EXPECT_NE(islands.of_item[0], islands.of_item[1]);
  EXPECT_NE(islands.of_item[1], islands.of_item[3]);
  EXPECT_EQ(islands.of_item[4], -1);
  EXPECT_EQ(islands.of_body[0], islands.of_body[2]);
  // numbered in the order of their first item, items in order within each
  EXPECT_EQ(islands.of_item[0], 0);
  const int k = islands.of_item[0];
  ASSERT_EQ(islands.item_start[k + 1] - islands.item_start[k], 2);
  EXPECT_EQ(islands.items[islands.item_start[k]], 0);
  EXPECT_EQ(islands.items[islands.item_start[k] + 1], 2);
}

TEST(Islands, AKinematicBodyLinksNothing) {
  // two boxes resting on one kinematic platform (body 1) are two islands
  IslandScratch islands;
  islands.links = {{0, 1}, {2, 1}};
  find_islands(bodies(3, {1}), islands);
  EXPECT_EQ(islands.count, 2);
  EXPECT_NE(islands.of_item[0], islands.of_item[1]);
  EXPECT_EQ(islands.of_body[1], -1);
  for (int i = 0; i < islands.count; ++i) EXPECT_TRUE(islands.logs[i].stale.empty());
}
