// Contact points of the narrow phase: a point of one body found inside (or, for speculative
// contacts, near) another body or the ground, and the reduction of a pair's points to at most
// four per direction of push. Pure functions of the points: no world, no bodies.
#pragma once

#include "math/types.h"

#include <vector>

namespace simbake {

// A point of body `a` found inside body `b` (or the ground, b < 0) at the candidates
struct Penetration {
  int a, b;
  Vec3 x;      // world position of the point (m)
  Vec3 n;      // unit normal of b's level set at x, world, pointing towards a
  double phi;  // b's signed distance at x (m), negative inside (positive: a speculative point)
  Vec3 local;  // the point in a's mesh frame: a surface sample, or a point of a box's exact
               // contact (see box_pair_contact, box_edge_crossing in narrow_phase.cpp)
  double s = 1.0;  // fraction of the step at which x, n and phi were taken (1: the candidates;
                   // less for a fast pair, see sweep_tests in narrow_phase.cpp); x is then where the point
                   // is at the candidates, so that lever arms are from the candidate centres
  // a point carried by both bodies (an edge crossing an edge, a box's exact contact): the
  // matching point of b in b's mesh frame, and the normal in b's frame; phi is then the
  // separation of the two points along the normal, not b's level set
  bool crossing = false;
  Vec3 local_b = Vec3::Zero();
  Vec3 normal_b = Vec3::Zero();
};

// Whether l is deeper than r (the order of a pair's points: deepest first)
inline bool deeper(const Penetration& l, const Penetration& r) { return l.phi < r.phi; }

// Sorts the points deepest first, keeping the order of equally deep ones (as std::stable_sort)
void sort_deepest_first(std::vector<Penetration>& points);

// Keeps at most four of a group of points that push the same way, `points` sorted deepest
// first: the deepest, the one farthest from it, the one that spans the largest triangle with
// those two, and the one farthest outside that triangle. Deterministic: ties go to the earlier
void reduce_to_four(std::vector<Penetration>& points);

// Reduces the points of one pair and direction (deepest first) group by group: a group is
// every remaining point whose normal is within ~25 degrees of the deepest remaining one's
void reduce_contact_points(std::vector<Penetration>& points);

}  // namespace simbake
