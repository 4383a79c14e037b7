// Intersecting triangle pairs of a triangle mesh: the check that a cloth does not pass through
// itself, written apart from any solver so that it can judge one.
//
// Two triangles that share no vertex intersect when an edge of one crosses the other
// (the segment between the end points of their intersection starts and ends where an edge
// of one pierces the other). Each segment-triangle test uses signed volumes only:
//   the segment pq crosses the plane of abc   iff  orient(a,b,c,p) and orient(a,b,c,q) have
//                                                  opposite signs,
//   and passes inside abc                     iff  orient(p,q,a,b), orient(p,q,b,c),
//                                                  orient(p,q,c,a) have one sign,
// with orient(a,b,c,d) = (b-a) x (c-a) . (d-a). A volume within 1e-10 L^3 of zero (L the
// longest edge of the two triangles) counts as zero: touching, coplanar triangles (two layers
// pressed flat onto one face, where every volume is round-off) and crossings shallower than
// about 1e-10 L do not count.
//
// Candidates come from a uniform grid (cell = the mean edge length) over the triangles'
// boxes; a pair is tested only in the first cell its boxes share, so no pair is tested
// twice and the cost is near linear in the triangle count for a cloth of even triangles.
#pragma once

#include "math/types.h"

#include <utility>
#include <vector>

namespace simbake {

// Whether segment pq crosses the inside of triangle abc (the signed-volume test above),
// volumes within eps of zero counting as zero
bool segment_crosses_triangle(const Vec3& p, const Vec3& q, const Vec3& a, const Vec3& b, const Vec3& c, double eps);

// Whether triangles (a0, a1, a2) and (b0, b1, b2) cross (see above)
bool triangles_intersect(const Vec3& a0, const Vec3& a1, const Vec3& a2,
                         const Vec3& b0, const Vec3& b1, const Vec3& b2);

// Candidate pairs one call may test when asked to bound its work: about 10 s on one core.
constexpr long long kPairTestBudget = 200'000'000;
constexpr long long kNoPairTestLimit = -1;

// Every pair (i, j), i < j, of triangles that share no vertex and intersect, sorted.
// Work is bounded by `max_tests` (kNoPairTestLimit: unbounded): the candidate pairs (pairs in
// one grid cell, and each triangle too large for the grid against every other) are counted
// before any is tested, and more than max_tests is std::length_error. Crumpled or random
// triangles put many in one cell (100,000 random triangles in a unit cube: ~1e10 candidates),
// where the answer itself can be quadratic in the triangle count.
std::vector<std::pair<int, int>> intersecting_triangle_pairs(const Points& vertices, const Triangles& triangles,
                                                             long long max_tests = kNoPairTestLimit);

}  // namespace simbake
