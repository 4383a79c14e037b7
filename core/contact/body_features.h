// A body's sharp features (a box's corners and edges) against a cloth's triangles.
//
// The cloth's contacts with a body hold its vertices and edge points out of the body's level
// set; they cannot stop a body's corner or edge from poking through the inside of a cloth
// triangle (a box's corner into a sheet draped over it, a pole through a flag), since there
// the cloth's own points all lie outside. Here the body's features are the points: each
// corner and points along each edge (no further apart than a quarter of the cloth's mean
// edge), with the outward normal n_f of the faces meeting there (their normalized sum). For
// a feature f and a cloth triangle (a, b, c) at its candidate positions, with unit normal
// n_t turned so that n_t . n_f > 0, the plane lies at
//     phi = (a - f) . n_t
// ahead of f; when f's projection f + phi n_t falls inside the triangle (barycentric
// weights w all >= 0) and -band < phi < h, the triangle's point at w is a contact point at
// distance phi with normal n_t, handled as the cloth's other contacts are (the point pushed
// out to h, the change shared by the three vertices by weight and inverse mass, friction,
// the opposite momentum to the body). A plane behind the feature (phi < 0) counts only when
// the triangle's point there lies inside the body (the feature pierced it); otherwise it is
// a layer on the body's far side, which the feature never reached (the caller checks). Bridson, Fedkiw and Anderson 2002 treat body
// features against cloth triangles the same way as cloth points against body surfaces.
#pragma once

#include "math/types.h"

#include <vector>

namespace simbake {

// Points along the 12 edges of a box of half extents `half` centred at the origin (corners
// included, once each), at most `spacing` apart, and their outward normals
void box_edge_features(const Vec3& half, double spacing, std::vector<Vec3>& points, std::vector<Vec3>& normals);

// A feature f (outward normal nf) against triangle (a, b, c): true when f's projection lies
// inside the triangle and the plane is within (-band, h) ahead of f; then the barycentric
// weights w, the normal n_t (turned towards nf) and the distance phi
bool feature_against_triangle(const Vec3& f, const Vec3& nf, const Vec3& a, const Vec3& b, const Vec3& c,
                              double h, double band, Vec3& w, Vec3& normal, double& phi);

// A uniform grid over triangles' boxes (grown by a margin): the triangles whose box may hold
// a point. Entries are sorted by (cell, triangle), so queries list triangles in index order.
class TriangleGrid {
 public:
  void build(const Points& x, const Triangles& triangles, double cell, double margin);
  // the triangles whose grown box's cells include p's cell, in increasing order
  void query(const Vec3& p, std::vector<int>& out) const;

 private:
  long long key(const Vec3& p) const;
  double cell_ = 1.0;
  std::vector<std::pair<long long, int>> entries_;  // (cell key, triangle), sorted
};

}  // namespace simbake
