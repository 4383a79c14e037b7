// Closest points between simple shapes, shared by self-collision (cloth/self_collision.cpp)
// and the cloth's contacts with body edges (contact/cloth_body_contact.cpp).
#pragma once

#include "math/types.h"

#include <utility>

namespace simbake {

// Parameters (s, t) in [0, 1] of the closest points p0 + s (p1 - p0) and q0 + t (q1 - q0) of
// segments p0 p1 and q0 q1 (Ericson, "Real-Time Collision Detection", 5.1.9); a degenerate
// segment is its point; for parallel ones, one of their pairs of closest points
std::pair<double, double> closest_on_segments(const Vec3& p0, const Vec3& p1, const Vec3& q0, const Vec3& q1);

// Closest point of triangle abc to p, as barycentric weights (u, v, w) of a, b, c
// (Ericson, "Real-Time Collision Detection", 5.1.5)
Vec3 closest_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c);

}  // namespace simbake
