// Points inside a closed triangle mesh, and how deep: the QA's check that cloth stays out of a
// deforming collider (pipeline/simbake/qa_deforming.py), written apart from any solver so that
// it can judge one.
//
// Inside is the parity of the triangles a ray from the point crosses, in a direction no
// mesh's edges or vertices line up with (a ray through an edge would count it twice). The
// triangles are binned in a grid across the ray (cell: half the median of their extents across
// it), so a point tests only the few in its column. Depth is the distance to the nearest
// triangle, exact: a grid of the triangles' boxes searched ring by ring until the next ring
// is further than the nearest found. Points outside the mesh's box are outside.
#pragma once

#include "math/types.h"

#include <memory>
#include <mutex>
#include <vector>

namespace simbake {

// (k x 2) vertex indices of edges
using Edges = Eigen::Matrix<std::int32_t, Eigen::Dynamic, 2, Eigen::RowMajor>;

class ClosedMesh {
 public:
  ClosedMesh(const Points& vertices, const Triangles& triangles);

  // The ray's direction (unit): a fixed lean along the axis the mesh's box is thinnest in
  const Vec3& ray() const { return frame_.ray; }

  bool inside(const Vec3& p) const;
  // Distance from p to the nearest triangle (infinity for a mesh with none)
  double distance(const Vec3& p) const;

 private:
  void bin_spatially() const;

  // the ray, and two unit vectors across it
  struct RayFrame {
    explicit RayFrame(int axis = 1);
    Eigen::Vector2d across(const Vec3& p) const { return {p.dot(u), p.dot(w)}; }
    Vec3 ray, u, w;
  };

  RayFrame frame_;
  std::vector<Vec3> a_, b_, c_;  // each triangle's corners
  Box3 box_;
  // the column grid across the ray: cells (cx, cy) at origin + cell * (cx, cy), each cell's
  // triangles at start_[key] .. start_[key + 1] of column_triangles_
  double cell_ = 1.0;
  Eigen::Vector2d origin_ = Eigen::Vector2d::Zero();
  int width_ = 0, height_ = 0;
  std::vector<int> start_, column_triangles_;
  // a triangle as a ray meets it, in one record: its box and corners across the ray, and the
  // corners' heights along it
  struct Crossing {
    Eigen::Vector2d lo, hi, a, b, c;
    Vec3 along;
  };
  std::vector<Crossing> crossings_;
  // the triangles' boxes binned in space (cubes of space_cell_ from box_'s corner), built
  // at the first distance asked for (once, by whichever thread asks first)
  std::unique_ptr<std::once_flag> space_built_ = std::make_unique<std::once_flag>();
  mutable std::vector<int> space_start_, space_triangles_;
  mutable double space_cell_ = 0.0;
  mutable Eigen::Vector3i space_size_ = Eigen::Vector3i::Zero();
};

// The deepest of `points` inside the mesh (each one's distance to its surface, 0 when none
// is inside) and the deepest of each edge's eighths (edge points at 1/8 .. 7/8 of it); the
// points in parallel, on the caller's arena (the maximum is the same in any order)
struct ClosedMeshDepth {
  double vertex = 0.0;
  double edge = 0.0;
};
ClosedMeshDepth closed_mesh_depth(const ClosedMesh& mesh, const Points& points, const Edges& edges);

}  // namespace simbake
