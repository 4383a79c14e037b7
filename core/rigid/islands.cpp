#include "rigid/islands.h"

#include <numeric>

namespace simbake {

void reset_sets(std::vector<int>& parent, int n) {
  parent.resize(n);
  std::iota(parent.begin(), parent.end(), 0);
}

int set_root(std::vector<int>& parent, int i) {
  while (parent[i] != i) i = parent[i] = parent[parent[i]];
  return i;
}

void find_islands(const std::vector<RigidBodyDef>& defs, IslandScratch& islands) {
  const int n = static_cast<int>(defs.size());
  const std::vector<std::array<int, 2>>& links = islands.links;
  std::vector<int>& parent = islands.parent;
  reset_sets(parent, n);
  auto root = [&](int i) { return set_root(parent, i); };
  auto dynamic = [&](int i) { return i >= 0 && !defs[i].kinematic; };
  for (const auto& [a, b] : links) {
    if (dynamic(a) && dynamic(b)) parent[root(a)] = root(b);
  }
  // each item's island is that of its dynamic body (a pair or contact has one at least)
  std::vector<int>& index = islands.index;
  std::vector<int>& of_item = islands.of_item;
  index.assign(n, -1);
  of_item.resize(links.size());
  islands.count = 0;
  for (std::size_t k = 0; k < links.size(); ++k) {
    const auto& [a, b] = links[k];
    of_item[k] = -1;
    if (a < 0) continue;
    const int r = root(dynamic(a) ? a : b);
    if (index[r] < 0) index[r] = islands.count++;
    of_item[k] = index[r];
  }
  std::vector<int>& of_body = islands.of_body;
  of_body.resize(n);
  for (int i = 0; i < n; ++i) of_body[i] = index[root(i)];
  // items by island (a counting sort keeps their order)
  std::vector<int>& start = islands.item_start;
  start.assign(islands.count + 1, 0);
  for (int island : of_item) {
    if (island >= 0) ++start[island + 1];
  }
  std::partial_sum(start.begin(), start.end(), start.begin());
  std::vector<int>& filled = islands.filled;
  filled.assign(start.begin(), start.end() - 1);
  islands.items.resize(start.back());
  for (std::size_t k = 0; k < links.size(); ++k) {
    if (of_item[k] >= 0) islands.items[filled[of_item[k]]++] = static_cast<int>(k);
  }
  if (static_cast<int>(islands.logs.size()) < islands.count) islands.logs.resize(islands.count);
  for (int k = 0; k < islands.count; ++k) {
    islands.logs[k].stale.clear();
    islands.logs[k].impulses = 0;
  }
}

}  // namespace simbake
