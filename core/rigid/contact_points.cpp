#include "rigid/contact_points.h"

#include <algorithm>
#include <utility>

namespace simbake {

// Keeps at most four of a group of penetrating points that push the same way: the deepest,
// the one farthest from it, the one that spans the largest triangle with those two, and the
// one farthest outside that triangle. A rigid body's velocity is linear in position, so if
// these points stop approaching so does every point of the flat contact they span; for a
// face on a face this replaces ~16 points by 4 for the same answer. Deterministic: ties go
// to the earlier point. `points` is sorted deepest first.
void reduce_to_four(std::vector<Penetration>& points) {
  const std::size_t count = points.size();
  if (count <= 4) return;
  std::size_t keep[4] = {0, 0, 0, 0};
  for (std::size_t round = 1; round < 4; ++round) {
    const Vec3 &p0 = points[keep[0]].x, &p1 = points[keep[1]].x, &p2 = points[keep[2]].x;
    const Vec3 normal = (p1 - p0).cross(p2 - p0);
    double best = -1.0;
    for (std::size_t k = 0; k < count; ++k) {
      const Vec3& x = points[k].x;
      double score;
      if (round == 1) {
        score = (x - p0).squaredNorm();
      } else if (round == 2) {
        score = (p1 - p0).cross(x - p0).squaredNorm();
      } else {  // outside the triangle: the largest of its distances beyond the three edges
        score = 0.0;
        for (const auto& [from, to] : {std::pair{p0, p1}, std::pair{p1, p2}, std::pair{p2, p0}}) {
          const Vec3 c = (to - from).cross(x - from);
          if (c.dot(normal) < 0.0) score = std::max(score, c.squaredNorm());
        }
      }
      if (score > best) {
        best = score;
        keep[round] = k;
      }
    }
  }
  // the kept points to the front, in their order of choice (distinct: a point chosen twice
  // is kept once)
  Penetration kept[4];
  std::size_t n = 0;
  for (std::size_t round = 0; round < 4; ++round) {
    if (std::find(keep, keep + round, keep[round]) == keep + round) kept[n++] = points[keep[round]];
  }
  points.assign(kept, kept + n);
}

void sort_deepest_first(std::vector<Penetration>& points) {
  // insertion sort: stable, as std::stable_sort, and a pair has a few dozen points at most
  // (no buffer to allocate)
  for (std::size_t k = 1; k < points.size(); ++k) {
    if (!deeper(points[k], points[k - 1])) continue;
    Penetration moved = points[k];
    std::size_t j = k;
    for (; j > 0 && deeper(moved, points[j - 1]); --j) points[j] = points[j - 1];
    points[j] = moved;
  }
}

// Reduces the points of one pair and direction (deepest first) group by group: a group is
// every remaining point whose normal is within ~25 degrees of the deepest remaining one's,
// so points that push different ways (an edge caught on a side face, the two arms of a
// torus on a post) keep their own representatives
void reduce_contact_points(std::vector<Penetration>& points) {
  if (points.empty()) return;
  // one group (two boxes, a face on the ground: nearly always): reduced where it lies
  const Vec3 n0 = points.front().n;
  if (std::all_of(points.begin(), points.end(), [&](const Penetration& p) { return p.n.dot(n0) > 0.9; })) {
    reduce_to_four(points);
    return;
  }
  // (scratch kept per thread: the pairs are reduced in parallel, and a step allocates nothing)
  thread_local std::vector<Penetration> rest, result, group, others;
  rest.clear();
  result.clear();
  rest.swap(points);
  while (!rest.empty()) {
    group.clear();
    others.clear();
    const Vec3 n0 = rest.front().n;
    for (const Penetration& p : rest) (p.n.dot(n0) > 0.9 ? group : others).push_back(p);
    reduce_to_four(group);
    result.insert(result.end(), group.begin(), group.end());
    rest.swap(others);
  }
  points.swap(result);
}

}  // namespace simbake
