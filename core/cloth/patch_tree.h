// A bounding volume hierarchy over a triangle mesh whose nodes are patches of its surface,
// and the test that a patch cannot touch itself while its vertices stay in given boxes: the
// broad phase of self-collision (cloth/self_collision.h) skips the pairs inside such a patch,
// so that a smooth sheet costs its few bent places and not its every neighbouring pair.
//
// A patch is flat over a step, its vertices moving from x to x + dt v, when:
//   1. normal cone: every triangle's normal n(s), s in [0, 1] of the step, keeps
//      n(s) . a >= 0.1 |n(s)| for one direction a (within acos 0.1 = 84 degrees of it;
//      Volino and Magnenat-Thalmann, "Efficient self-collision detection on smoothly
//      discretized surface animations using geometrical shape regularity", 1994), so that
//      the projection along a maps each triangle onto the plane with its orientation kept;
//   2. star contour: the patch is a disk, its boundary one loop, and the projection of every
//      triangle (c, u, w) of an inner vertex c (its centre) and a boundary edge u w, in the
//      boundary's orientation, keeps a positive area over the step (Schvartzman, Perez and
//      Otaduy, "Star-contours for efficient hierarchical self-collision detection", 2010):
//      the projected boundary is star-shaped around c, each edge turning it forward;
//   3. it winds once around c at the step's start (by 2, its winding cannot change).
// Then the projection maps the patch one to one onto the plane at every instant of the step
// (each projected point of the disk is covered once: the boundary's winding number, each
// triangle counting +1), so no two of its points meet: a point cannot touch a triangle it is
// not a vertex of, nor an edge another it shares no vertex with. n(s) is quadratic in s, as
// are the areas of 2: their three Bernstein coefficients on [0, 1] bound them (n(s) is a
// convex combination of them).
//
// Nodes split their triangles in two at the median of their centroids along the longest
// side of the centroids' box (at the positions the tree is built with), down to leaves of
// at most 8 triangles. A patch that is not a disk (a bowtie, an annulus, a non-manifold or
// inconsistently oriented piece), or has no inner vertex, is never flat.
#pragma once

#include "math/types.h"

#include <Eigen/Core>

#include <array>
#include <vector>

namespace simbake {

class PatchTree {
 public:
  struct Node {
    Box3 box;                          // the union of its triangles' boxes
    int child[2] = {-1, -1};           // -1 for a leaf
    int parent = -1;
    int begin = 0, end = 0;            // its triangles: order()[begin, end)
    int leaf_begin = 0, leaf_end = 0;  // its leaves [leaf_begin, leaf_end)
    int centre = -1;                   // an inner vertex, or -1: not a disk with one (never flat)
    int loop_begin = 0, loop_end = 0;  // its boundary loop: loop()[loop_begin, loop_end), in the triangles' orientation
    bool leaf() const { return child[0] < 0; }
  };

  PatchTree() = default;
  // the tree over `ids` (rows of `triangles`), split at the positions x (n x 3, n >= every
  // vertex index); without `patches`, a tree of boxes only, whose nodes are never flat
  PatchTree(const Triangles& triangles, std::vector<int> ids, const Points& x, bool patches = true);

  bool empty() const { return nodes_.empty(); }
  const std::vector<Node>& nodes() const { return nodes_; }
  const std::vector<int>& order() const { return order_; }  // the triangles, node by node
  const std::vector<int>& loop() const { return loop_; }
  int leaf_count() const { return static_cast<int>(leaf_node_.size()); }
  int leaf_node(int leaf) const { return leaf_node_[leaf]; }  // the node of a leaf
  int leaf_of(int triangle) const { return leaf_of_[triangle]; }  // -1 for a triangle not in the tree

  // every node's box from its triangles' (triangle_boxes: one per row of the triangles)
  void refit(const std::vector<Box3>& triangle_boxes);
  // the boxes of the nodes above `changed` triangles only
  void refit(const std::vector<Box3>& triangle_boxes, const std::vector<int>& changed);
  // whether `node` is flat over the step from x to x + dt v (see the top), given each
  // triangle's normal over it by its Bernstein coefficients (one per row of the triangles)
  // and the largest of their norms
  bool flat(int node, const std::vector<std::array<Vec3, 3>>& normal, const std::vector<double>& largest,
            const Points& x, const Points& v, double dt) const;

 private:
  std::vector<Node> nodes_;
  std::vector<int> order_, loop_, leaf_node_, leaf_of_;

  int build(std::vector<int>& ids, int begin, int end, int parent, const std::vector<Vec3>& centroid);
  void find_loops(const Triangles& triangles, const Points& x);
  void refit_node(int n, const std::vector<Box3>& triangle_boxes);
};

}  // namespace simbake
