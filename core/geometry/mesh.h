// Closed triangle meshes: the surface of a rigid body, its collision samples, its USD mesh.
#pragma once

#include "math/types.h"

#include <array>
#include <vector>

namespace simbake {

struct TriangleMesh {
  Points vertices;      // (n x 3) positions (m)
  Triangles triangles;  // (m x 3) vertex indices, counter-clockwise seen from outside
};

// Area-weighted vertex normals, unit length. Accumulated from zero: each triangle adds its
// (unnormalized) face normal, whose length is twice its area, to its three vertices.
// A vertex used by no triangle (or only degenerate ones) gets +y.
Points vertex_normals(const TriangleMesh& mesh);

// The most subdivisions a sphere or box mesh takes: 12 * 512^2 = 3.1 million triangles (about
// 250 MB while it is built); more is std::invalid_argument, before anything is allocated.
constexpr int kMaxSubdivisions = 512;

// Sphere of the given radius centred at the origin: a cube whose faces are split into
// subdivisions x subdivisions quads (two triangles each), every vertex projected onto the
// sphere. 6 * s^2 + 2 vertices, 12 * s^2 triangles; s in [1, kMaxSubdivisions].
TriangleMesh make_sphere_mesh(double radius, int subdivisions);

// Axis-aligned box with the given full edge lengths, centred at the origin, each face split
// into subdivisions x subdivisions quads (vertices shared along edges, so the mesh is closed).
TriangleMesh make_box_mesh(const Vec3& size, int subdivisions);

// Collision samples of a surface: every vertex, then points spaced at most max_spacing
// apart along every edge longer than that (so that a coarse mesh's edges can still catch
// another body's level set), in a deterministic order (edges sorted by vertex indices).
Points surface_samples(const TriangleMesh& mesh, double max_spacing);

// Every edge of the triangles once, as (i, j) with i < j, sorted
std::vector<std::array<int, 2>> unique_edges(const Triangles& triangles);

// True when every edge is shared by exactly two triangles with opposite orientation
bool is_closed(const TriangleMesh& mesh);

}  // namespace simbake
