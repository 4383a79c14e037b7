#include "rigid/overlapping_pairs.h"

#include <algorithm>
#include <cmath>
#include <numeric>

namespace simbake {

void overlapping_pairs(const std::vector<Box3>& boxes, GridScratch& grid, std::vector<std::pair<int, int>>& out) {
  constexpr long long kMaxCells = 64;
  out.clear();
  const int n = static_cast<int>(boxes.size());
  // cell width: the median of the boxes' largest sides; the grid over the finite boxes
  std::vector<double>& sides = grid.sides;
  sides.clear();
  Box3 all;
  for (int i = 0; i < n; ++i) {
    if (!boxes[i].min().allFinite() || !boxes[i].max().allFinite()) continue;
    sides.push_back(boxes[i].sizes().maxCoeff());
    all.extend(boxes[i]);
  }
  double cell = 1.0;
  if (!sides.empty()) {
    std::nth_element(sides.begin(), sides.begin() + sides.size() / 2, sides.end());
    cell = std::max(sides[sides.size() / 2], 1e-6 * all.sizes().maxCoeff());
    if (!(cell > 0.0)) cell = 1.0;
  }
  // no more cells than a few per box: a scattered scene gets wider cells
  const long long budget = 4LL * n + 64;
  Eigen::Array<long long, 3, 1> dims;
  for (;;) {
    for (int k = 0; k < 3; ++k) {
      dims[k] = sides.empty() ? 1 : static_cast<long long>(std::floor(all.sizes()[k] / cell)) + 1;
    }
    if (dims.prod() <= budget) break;
    cell *= 2.0;
  }
  const Vec3 origin = sides.empty() ? Vec3::Zero() : all.min();
  auto cell_of = [&](const Vec3& p) {
    Eigen::Array<long long, 3, 1> c;
    for (int k = 0; k < 3; ++k) {
      c[k] = std::clamp(static_cast<long long>(std::floor((p[k] - origin[k]) / cell)), 0LL, dims[k] - 1);
    }
    return c;
  };
  auto index_of = [&](const Eigen::Array<long long, 3, 1>& c) { return (c[2] * dims[1] + c[1]) * dims[0] + c[0]; };
  // each box's cell range; large boxes apart
  std::vector<int>& large = grid.large;
  std::vector<std::array<long long, 6>>& ranges = grid.ranges;
  large.clear();
  ranges.resize(n);
  std::vector<int>& start = grid.cell_start;
  start.assign(dims.prod() + 1, 0);
  for (int i = 0; i < n; ++i) {
    const Box3& box = boxes[i];
    const auto lo = cell_of(box.min()), hi = cell_of(box.max());
    if (!box.min().allFinite() || !box.max().allFinite() || (hi - lo + 1).prod() > kMaxCells) {
      large.push_back(i);
      ranges[i][0] = -1;
      continue;
    }
    ranges[i] = {lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]};
    for (long long z = lo[2]; z <= hi[2]; ++z)
      for (long long y = lo[1]; y <= hi[1]; ++y)
        for (long long x = lo[0]; x <= hi[0]; ++x) ++start[index_of({x, y, z}) + 1];
  }
  std::partial_sum(start.begin(), start.end(), start.begin());
  std::vector<int>& members = grid.members;
  std::vector<int>& filled = grid.filled;
  members.resize(start.back());
  filled.assign(start.begin(), start.end() - 1);
  for (int i = 0; i < n; ++i) {
    const auto& r = ranges[i];
    if (r[0] < 0) continue;  // large
    for (long long z = r[2]; z <= r[5]; ++z)
      for (long long y = r[1]; y <= r[4]; ++y)
        for (long long x = r[0]; x <= r[3]; ++x) members[filled[index_of({x, y, z})]++] = i;
  }
  // pairs within a cell, reported only by the cell of their intersection's lower corner
  for (long long c = 0; c + 1 < static_cast<long long>(start.size()); ++c) {
    for (int u = start[c]; u < start[c + 1]; ++u) {
      for (int w = u + 1; w < start[c + 1]; ++w) {
        const int i = members[u], j = members[w];
        if (!boxes[i].intersects(boxes[j])) continue;
        // (the cell of the larger of two lower corners is the larger of their cells)
        const auto &ri = ranges[i], &rj = ranges[j];
        if (index_of({std::max(ri[0], rj[0]), std::max(ri[1], rj[1]), std::max(ri[2], rj[2])}) != c) continue;
        out.emplace_back(std::min(i, j), std::max(i, j));
      }
    }
  }
  for (int i : large) {
    for (int j = 0; j < n; ++j) {
      if (j == i || (ranges[j][0] < 0 && j < i)) continue;  // a pair of large boxes once
      if (boxes[i].intersects(boxes[j])) out.emplace_back(std::min(i, j), std::max(i, j));
    }
  }
  std::sort(out.begin(), out.end());
}

}  // namespace simbake
