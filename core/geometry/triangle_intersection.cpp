#include "geometry/triangle_intersection.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>
#include <tuple>

namespace simbake {

namespace {

double orient(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d) {
  return (b - a).cross(c - a).dot(d - a);
}

using Cell = std::array<int, 3>;

// A triangle's box in cells (inclusive)
struct CellRange {
  Cell lo, hi;
};

constexpr long long kMaxCells = 512;

// The pairs the search below would test: each cell's pairs, and each large triangle against
// every other; std::length_error when they are more than max_tests (nothing tested yet)
void check_test_count(const std::vector<size_t>& group_starts, long long large, long long m, long long max_tests) {
  long double tests = static_cast<long double>(large) * static_cast<long double>(m);
  for (size_t k = 0; k + 1 < group_starts.size(); ++k) {
    const long double n = static_cast<long double>(group_starts[k + 1] - group_starts[k]);
    tests += 0.5L * n * (n - 1.0L);
  }
  if (tests > static_cast<long double>(max_tests)) {
    char shown[96];
    std::snprintf(shown, sizeof shown, "%.3Lg candidate pairs, more than the budget of %lld", tests, max_tests);
    throw std::length_error(std::string("intersecting_triangle_pairs: ") + shown +
                            " (triangles crowded into one place, or far larger than their mean edge)");
  }
}
constexpr double kRoundOff = 1e-10;  // signed volumes under this x L^3 are zero (L: the longest edge)

}  // namespace

bool segment_crosses_triangle(const Vec3& p, const Vec3& q, const Vec3& a, const Vec3& b, const Vec3& c, double eps) {
  const double sp = orient(a, b, c, p), sq = orient(a, b, c, q);
  if (!((sp < -eps && sq > eps) || (sp > eps && sq < -eps))) return false;
  const double u = orient(p, q, a, b), v = orient(p, q, b, c), w = orient(p, q, c, a);
  return (u > eps && v > eps && w > eps) || (u < -eps && v < -eps && w < -eps);
}

bool triangles_intersect(const Vec3& a0, const Vec3& a1, const Vec3& a2,
                         const Vec3& b0, const Vec3& b1, const Vec3& b2) {
  const double edge = std::max({(a1 - a0).norm(), (a2 - a1).norm(), (a0 - a2).norm(), (b1 - b0).norm(),
                                (b2 - b1).norm(), (b0 - b2).norm()});
  const double eps = kRoundOff * edge * edge * edge;
  return segment_crosses_triangle(a0, a1, b0, b1, b2, eps) || segment_crosses_triangle(a1, a2, b0, b1, b2, eps) ||
         segment_crosses_triangle(a2, a0, b0, b1, b2, eps) || segment_crosses_triangle(b0, b1, a0, a1, a2, eps) ||
         segment_crosses_triangle(b1, b2, a0, a1, a2, eps) || segment_crosses_triangle(b2, b0, a0, a1, a2, eps);
}

std::vector<std::pair<int, int>> intersecting_triangle_pairs(const Points& x, const Triangles& t, long long max_tests) {
  const int m = static_cast<int>(t.rows());
  std::vector<std::pair<int, int>> pairs;
  if (m < 2) return pairs;

  // triangle boxes and the cell size: the mean edge length
  std::vector<Box3> boxes(m);
  double edge_sum = 0.0;
  for (int i = 0; i < m; ++i) {
    const Vec3 p0 = x.row(t(i, 0)).transpose(), p1 = x.row(t(i, 1)).transpose(), p2 = x.row(t(i, 2)).transpose();
    boxes[i] = Box3(p0);
    boxes[i].extend(p1);
    boxes[i].extend(p2);
    edge_sum += (p1 - p0).norm() + (p2 - p1).norm() + (p0 - p2).norm();
  }
  const double mean_edge = edge_sum / (3.0 * m);
  const double h = std::isfinite(mean_edge) && mean_edge > 0.0 ? mean_edge : 1.0;
  const auto cell_of = [h](double v) { return static_cast<int>(std::floor(std::clamp(v / h, -1e9, 1e9))); };

  // grid entries (cell, triangle); triangles over too many cells go to `large`
  std::vector<CellRange> ranges(m);
  std::vector<std::tuple<Cell, int>> entries;
  std::vector<int> large;
  entries.reserve(4 * static_cast<size_t>(m));
  for (int i = 0; i < m; ++i) {
    CellRange& r = ranges[i];
    long long count = 1;
    for (int k = 0; k < 3; ++k) {
      r.lo[k] = cell_of(boxes[i].min()[k]);
      r.hi[k] = cell_of(boxes[i].max()[k]);
      count *= static_cast<long long>(r.hi[k]) - r.lo[k] + 1;
    }
    if (count > kMaxCells || !boxes[i].min().allFinite() || !boxes[i].max().allFinite()) {
      large.push_back(i);
      continue;
    }
    for (int a = r.lo[0]; a <= r.hi[0]; ++a)
      for (int b = r.lo[1]; b <= r.hi[1]; ++b)
        for (int c = r.lo[2]; c <= r.hi[2]; ++c) entries.emplace_back(Cell{a, b, c}, i);
  }
  std::sort(entries.begin(), entries.end());
  std::vector<size_t> group_starts;
  for (size_t e = 0; e < entries.size(); ++e) {
    if (e == 0 || std::get<0>(entries[e]) != std::get<0>(entries[e - 1])) group_starts.push_back(e);
  }
  group_starts.push_back(entries.size());
  if (max_tests != kNoPairTestLimit) check_test_count(group_starts, static_cast<long long>(large.size()), m, max_tests);

  const auto share_vertex = [&t](int i, int j) {
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b)
        if (t(i, a) == t(j, b)) return true;
    return false;
  };
  const auto crosses = [&](int i, int j) {
    if (share_vertex(i, j) || !boxes[i].intersects(boxes[j])) return false;
    return triangles_intersect(x.row(t(i, 0)).transpose(), x.row(t(i, 1)).transpose(), x.row(t(i, 2)).transpose(),
                               x.row(t(j, 0)).transpose(), x.row(t(j, 1)).transpose(), x.row(t(j, 2)).transpose());
  };

  // each cell's pairs, tested only in the first cell both boxes cover (the cell of the
  // larger of their lower corners), in parallel; per-thread lists sorted at the end
  tbb::enumerable_thread_specific<std::vector<std::pair<int, int>>> found;
  tbb::parallel_for(tbb::blocked_range<size_t>(0, group_starts.size() - 1, 64), [&](const tbb::blocked_range<size_t>& g) {
    auto& out = found.local();
    for (size_t k = g.begin(); k != g.end(); ++k) {
      const size_t begin = group_starts[k], end = group_starts[k + 1];
      const Cell& cell = std::get<0>(entries[begin]);
      for (size_t p = begin; p < end; ++p) {
        const int i = std::get<1>(entries[p]);
        for (size_t q = p + 1; q < end; ++q) {
          const int j = std::get<1>(entries[q]);
          const Cell first{std::max(ranges[i].lo[0], ranges[j].lo[0]), std::max(ranges[i].lo[1], ranges[j].lo[1]),
                           std::max(ranges[i].lo[2], ranges[j].lo[2])};
          if (first != cell || !crosses(i, j)) continue;
          out.emplace_back(std::min(i, j), std::max(i, j));
        }
      }
    }
  });
  for (const auto& list : found) pairs.insert(pairs.end(), list.begin(), list.end());
  // large triangles against every other (a pair of two large ones once)
  std::vector<char> is_large(m, 0);
  for (int i : large) is_large[i] = 1;
  for (int i : large) {
    for (int j = 0; j < m; ++j) {
      if (j == i || (is_large[j] && j < i) || !crosses(i, j)) continue;
      pairs.emplace_back(std::min(i, j), std::max(i, j));
    }
  }
  std::sort(pairs.begin(), pairs.end());
  return pairs;
}

}  // namespace simbake
