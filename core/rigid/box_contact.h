// Contact between two boxes, exactly: the separating-axis test and clipping.
//
// Sample points on a box find its faces against another body but miss an edge crossing an
// edge between samples: two 0.5 m boxes with samples 0.125 m apart can cross edges by a good
// part of that spacing while no sample is inside. For two boxes the contact can be
// found exactly, as game engines do (Gottschalk, Lin and Manocha 1996 for the 15 separating
// axes; Ericson, "Real-Time Collision Detection" 2005, 5.2 and 4.4, for the clipping):
//  - the axis of least overlap among the 15 candidates (3 face normals of each box, 9 cross
//    products of their edges) is the contact normal and its overlap the depth: for convex
//    polyhedra that is the shortest translation that separates them;
//  - a face axis: the reference face is that face, the incident face the other box's face
//    most opposed to it; the incident face is clipped to the reference face's side planes
//    and each remaining corner below the reference plane is a contact point (up to 8);
//  - an edge-edge axis: one point, the closest points of the two edges.
// Face axes are preferred over edge axes unless an edge axis is clearly shallower (a
// tolerance), so that a box resting on another keeps a face contact from step to step.
#pragma once

#include "levelset/signed_distance.h"
#include "math/types.h"
#include "rigid/rigid_body.h"

#include <array>

namespace simbake {

struct OrientedBox {
  Vec3 center;     // (m, world)
  Mat3 rotation;   // columns: the box's axes in world
  Vec3 half;       // half edge lengths along those axes (m)
};

struct BoxContactPoint {
  Vec3 x;          // a point of box a's surface (world, m)
  double depth;    // how far it is inside box b (m); negative: apart by that much (margin)
};

struct BoxContact {
  Vec3 normal = Vec3::Zero();  // unit, world, from box b towards box a
  double depth = 0.0;          // overlap along the normal (m): the separating-axis depth
  bool edge_edge = false;      // the normal is a cross product of two edges ...
  double edge_sine = 0.0;      // ... whose angle has this sine (0: parallel)
  int count = 0;               // points used
  std::array<BoxContactPoint, 8> points;
};

// The contact of box a with box b when they overlap or are apart by less than `margin` (m);
// false when they are farther apart. Points of the clipped face closer than `point_reach`
// outside count (depth < 0; point_reach is at least the margin).
// With `faces`, an edge-against-edge contact also gives there the contact along the
// shallowest face axis (the faces behind the edges, which may close within the step);
// faces->count is 0 otherwise.
bool box_box_contact(const OrientedBox& a, const OrientedBox& b, double margin, BoxContact& out,
                     BoxContact* faces = nullptr, double point_reach = 0.0);

// The same when that contact is an edge against an edge; false otherwise, without clipping
// any face (the narrow phase asks this of every pair of boxes)
bool box_edge_contact(const OrientedBox& a, const OrientedBox& b, double margin, BoxContact& out);

// How deep the boxes overlap: the least overlap of their projections on the 15 axes (the
// shortest translation that separates them), 0 when apart (m)
double box_overlap_depth(const OrientedBox& a, const OrientedBox& b);

// The box of a box shape (BoxDistance, centred at its mesh origin) at a mesh pose; false for
// any other shape
bool oriented_box(const SignedDistance* shape, const Pose& pose, OrientedBox& out);

}  // namespace simbake
