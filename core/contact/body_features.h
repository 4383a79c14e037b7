// A body's sharp features (a box's or a mesh's corners and edges) against a cloth's triangles.
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
// a layer on the body's far side, which the feature never reached (the caller checks).
// Bridson, Fedkiw and Anderson 2002 treat body features against cloth triangles the same way
// as cloth points against body surfaces.
//
// The features of a body are a list of points and normals in its own coordinates, made once
// per (body, cloth): a box's edges exactly (box_edge_features), a mesh's sharp convex edges
// and its corners (mesh_edge_features). Which of a mesh's edges are sharp depends on the
// cloth: a cloth triangle straddling a crease of exterior angle theta (the angle between
// the two faces' normals), its corners s from the crease and held h off both faces by the
// cloth's contacts, clears the crease's line by
//     h cos(theta / 2) - s sin(theta / 2),
// so it stays clear while tan(theta / 2) < h / s. s reaches the cloth's mean edge L, more
// under strain, and the level set's rounding of the crease (a fraction of a voxel) takes part
// of h, hence a factor 2 of margin: a crease is sharp past
//     theta_s = 2 atan(h / (2 L)),   and at most 30 degrees,
// (cloth_demo: h = 5 mm, L = 5 cm, theta_s = 5.7 degrees: every edge of its torus, whose
// faces meet at 11.25 and 22.5 degrees, is a feature).
#pragma once

#include "math/types.h"

#include <array>
#include <cmath>
#include <vector>

namespace simbake {

// A sharp edge of a body, in its own coordinates: from a to b, between faces of outward unit
// normals n1 and n2 (equal for a boundary edge). A point whose direction d from the edge
// (across it) has d . n1 > 0 or d . n2 > 0 is outside the body there (the edge is convex)
struct FeatureEdge {
  Vec3 a, b, n1, n2;
};

// Points along the 12 edges of a box of half extents `half` centred at the origin (corners
// included, once each), at most `spacing` apart, and their outward normals; and, if asked,
// the 12 edges themselves
void box_edge_features(const Vec3& half, double spacing, std::vector<Vec3>& points, std::vector<Vec3>& normals,
                       std::vector<FeatureEdge>* edges = nullptr);

// Points and their outward unit normals, in the body's coordinates (m)
struct BodyFeatures {
  std::vector<Vec3> points;   // (nfeature) on the body's surface (m)
  std::vector<Vec3> normals;  // (nfeature) the normalized sum of the normals of the faces there
  Box3 bounds;                // of the points (m)
  std::vector<FeatureEdge> edges;    // the sharp edges the points lie along, whole (ClothBodyContact's edge contacts)
  std::vector<double> inside_below;  // (nfeature) a point behind the feature is inside the body where the
                                     // body's phi is below this (m): 0, or the level set's own phi at the
                                     // feature where it rounds a sharp edge (see ClothBodyContact::collide_features)
};

// The exterior angle (rad) past which a mesh's crease is a feature for a cloth of thickness
// h and mean edge L (the derivation is at the top of this file)
double sharp_crease_angle(double thickness, double mean_edge);

// A closed mesh's features: points at most `spacing` apart along every convex edge whose
// faces meet at more than `sharp_angle` (rad) and every boundary edge, each with the
// normalized sum of its faces' normals; then the corners, once each, in vertex order: the
// ends of those edges, and any vertex whose faces all turn away (a positive angle deficit)
// with one of them more than sharp_angle / 2 from the vertex's normal (a cone's tip among
// shallow creases), each with its angle-weighted normal (the sum of its faces' normals
// weighted by their angles there: (1, 1, 1) / sqrt(3) at a cube's corner however its faces
// are split)
void mesh_edge_features(const Points& vertices, const Triangles& triangles, double spacing, double sharp_angle,
                        std::vector<Vec3>& points, std::vector<Vec3>& normals,
                        std::vector<FeatureEdge>* edges = nullptr);

// A feature f (outward normal nf) against triangle (a, b, c): true when f's projection lies
// inside the triangle and the plane is within (-band, h) ahead of f; then the barycentric
// weights w, the normal n_t (turned towards nf) and the distance phi
bool feature_against_triangle(const Vec3& f, const Vec3& nf, const Vec3& a, const Vec3& b, const Vec3& c,
                              double h, double band, Vec3& w, Vec3& normal, double& phi);
// The same in two parts, so that a triangle's plane can be kept for many features: its unit
// normal along (b - a) x (c - a) and twice its area (false, and 0, for a degenerate triangle);
// then the feature against it (false for a degenerate triangle)
bool triangle_plane(const Vec3& a, const Vec3& b, const Vec3& c, Vec3& winding, double& twice_area);
bool feature_against_plane(const Vec3& f, const Vec3& nf, const Vec3& a, const Vec3& b, const Vec3& c,
                           const Vec3& winding, double twice_area, double h, double band, Vec3& w, Vec3& normal,
                           double& phi);

// A uniform grid over triangles' boxes (grown by a margin): the triangles whose box may hold
// a point. A triangle is listed in every cell its grown box meets (clipped to the region
// grown by a cell), a cell named by its index along each axis wrapped to 21 bits (distinct
// cells may share a name, which only adds candidates); a query lists the triangles of its
// cell's name in index order. Held as buckets of a dense block of cells, filled by counting
// (no sort), when the block is small beside the entries; else as sorted (cell, triangle)
// entries. The two give the same lists (tests/cpp/contact/test_body_features.cpp).
class TriangleGrid {
 public:
  // the most cells of a dense block, per entry (a block larger than this is sorted instead)
  static constexpr long long kDenseCellsPerEntry = 4;
  // the triangles (at positions x) whose box grown by `margin` meets `region`; queries only
  // of points in `region` (or near it: what is in their cell); `dense` false: sorted entries
  // (`consider`: only those of these triangles, increasing, a list that holds every one that
  // qualifies; null: all)
  void build(const Points& x, const Triangles& triangles, double cell, double margin, const Box3& region,
             const std::vector<int>* consider = nullptr, bool dense = true);
  // the triangles whose grown box's cells include p's cell, in increasing order
  void query(const Vec3& p, std::vector<int>& out) const;
  // p's cell (two points in the same cell have the same query)
  long long cell(const Vec3& p) const { return key(p); }

 private:
  static constexpr long long kWrap = (1LL << 21) - 1;  // the mask of a cell's index along an axis
  long long index(double coordinate) const { return static_cast<long long>(std::floor(coordinate / cell_)); }
  long long key(const Vec3& p) const;
  // the dense block's cell holding the cells named like index i along each axis, or -1
  long long dense_cell(const std::array<long long, 3>& i) const;
  double cell_ = 1.0;
  bool dense_ = false;
  std::vector<std::pair<long long, int>> entries_;  // (cell key, triangle), sorted (not dense)
  // dense: the block of cells [base, base + size) by axis, wrapped indices unique in it
  std::array<long long, 3> base_{}, size_{};
  std::vector<int> starts_, ends_;  // (block cells) each bucket's range in items_
  std::vector<int> items_;          // the triangles of each bucket, increasing
  // scratch: the kept triangles and their cells' indices along each axis
  std::vector<int> kept_;
  std::vector<long long> indices_;             // along x, y, z per kept triangle, in turn
  std::vector<std::array<int, 4>> spans_;      // (kept) where its x, y, z indices start and end in indices_
};

}  // namespace simbake
