// What the parts of self-collision (self_collision*.cpp) share: constants, small helpers and
// the impulse of a contact. Internal to cloth/: include only from those files.
#pragma once

#include "cloth/self_collision.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <limits>
#include <vector>

namespace simbake::self_collision_detail {

constexpr double kRepulsionRate = 0.1;      // a pair closer than h separates by 0.1 (h - d) per step at most
constexpr double kCollisionTolerance = 1e-2; // of h: coplanar pairs this close count as colliding
constexpr double kSeparation = 1e-3;        // of h per step: the separating speed a collision impulse leaves
constexpr double kMaxHeldAmplification = 4.0;  // see apply_impulse
constexpr double kMargin = 0.1;             // of the mean edge: how far a vertex's box reaches past
                                            // its start and end of the step
constexpr size_t kMovedFraction = 8;       // all pairs are found again when more than 1 / 8 of the vertices
                                            // leave their boxes at once
constexpr size_t kChunk = 512;              // pairs per parallel task (fixed: same result at any thread count)
constexpr double kFlat = 0.1;               // a pivot's triangles are flat when their normals stay within
                                            // acos(0.1) = 84 degrees of one direction (any angle under 90
                                            // would do; the rest is room for round-off)

inline Vec3 row(const Points& p, int k) { return p.row(k).transpose(); }

// how close coplanar pairs count as colliding (m)
inline double collision_tolerance(const SelfCollisionSettings& settings) {
  return std::max(kCollisionTolerance * settings.thickness, 1e-9);
}

inline bool on_triangle(const Triangles& triangles, int t, int k) {
  return triangles(t, 0) == k || triangles(t, 1) == k || triangles(t, 2) == k;
}

// for_each(i, out) for i in [0, count), in parallel over fixed chunks; the outputs joined in
// order of i, so the result is the same at any thread count
template <class T, class ForEach>
void parallel_collect(size_t count, std::vector<T>& out, ForEach&& for_each) {
  const size_t chunks = (count + kChunk - 1) / kChunk;
  std::vector<std::vector<T>> found(chunks);
  tbb::parallel_for(size_t(0), chunks, [&](size_t chunk) {
    const size_t end = std::min(count, (chunk + 1) * kChunk);
    for (size_t i = chunk * kChunk; i < end; ++i) for_each(i, found[chunk]);
  });
  for (const auto& list : found) out.insert(out.end(), list.begin(), list.end());
}

// Applies an impulse along the contact's normal that brings the pair's relative normal
// velocity up to `target` (never down), with Coulomb friction on the relative slip limited
// by the same change; returns whether it did anything. With `support` (see
// SelfCollisionSettings::support), a vertex resting on a still surface (the normal of the
// surfaces it rests on this step, or zero) that the impulse would push into that surface
// takes none of it, as a pinned vertex: the surface holds it, and the pair's other vertices
// take the change
bool apply_impulse(const SelfCollision::Contact& c, double target, double friction, Points& v,
                   const Eigen::VectorXd& inverse_mass, const std::vector<Vec3>* support);

// A pair's distance at x (kind 0: point ids[0] and triangle ids[1..3]; kind 1: edges ids[0..1]
// and ids[2..3]) as a contact: the weights of the closest points, the normal from the second
// side towards the first (across both sides where they touch, closer than `touch`)
double pair_contact(int kind, const std::array<int, 4>& ids, const Points& x, double touch,
                    SelfCollision::Contact& c);

}  // namespace simbake::self_collision_detail
