// The cloth near a body: which of its vertices and edges a body's contacts need look at.
//
// A pass of the cloth's contacts (ClothBodyContact::collide) takes the bodies one after
// another, each against every cloth point whose candidate x + dt v lies in the body's box.
// Looking at every vertex and edge for every body made the pass cost (bodies x cloth). Here the
// candidates are put in a grid of cubes once per pass; a body then visits the vertices in the
// cubes its box meets, and the edges of the vertices in the cubes its box grown by the
// longest edge meets (an edge with a point in the box has both ends within its length of it).
// The contacts change the candidates as they go; a vertex they move is handed back (moved), and
// from then on it is visited by every body, its edges too, so that the points visited are a
// superset of those in the box at the moment each is looked at. The caller tests each point as
// before, in the same order (vertices and edges by increasing index): the contacts found are
// the same, in the same order, as when every point is looked at.
#pragma once

#include "math/types.h"

#include <array>
#include <vector>

namespace simbake {

class ClothNearby {
 public:
  ClothNearby() = default;
  ClothNearby(int vertex_count, const std::vector<std::array<int, 2>>& edges, const Triangles& triangles);

  // a pass begins: every vertex's candidate (nvert x 3, m)
  void begin(const Points& candidates);
  // vertex k's candidate has changed since begin
  void moved(int k) {
    if (moved_mark_[k] != pass_) {
      moved_mark_[k] = pass_;
      moved_.push_back(k);
    }
  }

  // the vertices whose candidate may lie in `box` now, increasing
  const std::vector<int>& vertices(const Box3& box);

  // the triangles whose box may meet `box` now, increasing
  const std::vector<int>& triangles(const Box3& box);

  // the edges that may have a point in `box` now, one by one, increasing: begin_edges, then
  // next_edge until it returns -1; the edges of a vertex moved meanwhile are added
  void begin_edges(const Box3& box);
  int next_edge();

 private:
  // the vertices in the cubes `box` meets, and those moved, unordered (into found_)
  void gather(const Box3& box);
  long long cube(int axis, double coordinate) const;
  // the items (edges or triangles, each marked mark_ in `marks`) of the vertices found_ (by
  // `start`, `items`: each vertex's, increasing), in increasing order, into found_
  void items_of_found(const std::vector<int>& start, const std::vector<int>& items, std::vector<int>& marks);

  int vertex_count_ = 0;
  std::vector<int> edge_start_, vertex_edges_;  // (nvert + 1), (2 nedge): each vertex's edges, increasing
  std::vector<int> triangle_start_, vertex_triangles_;  // (nvert + 1), (3 ntri): each vertex's triangles
  const std::vector<std::array<int, 2>>* edges_ = nullptr;

  // the grid of the pass's candidates: cubes [origin + size * i, origin + size * (i + 1)) of
  // a block of counts_[a] along each axis; all_ when the candidates do not suit a grid
  bool all_ = true;
  Vec3 origin_ = Vec3::Zero();
  double size_ = 1.0;
  std::array<long long, 3> counts_{};
  std::vector<int> starts_, items_;  // each cube's vertices, increasing
  double reach_ = 0.0;               // the longest edge along any axis at the pass's start (m)

  int pass_ = 0;
  std::vector<int> moved_mark_;  // (nvert) pass_ when moved in this pass
  std::vector<int> moved_;       // moved this pass, in the order they were

  // scratch
  int mark_ = 0;
  std::vector<int> vertex_mark_, edge_mark_, triangle_mark_;  // (nvert), (nedge), (ntri)
  std::vector<int> found_;                    // vertices (vertices()) or edges (begin_edges) found
  std::vector<int> ends_;                     // the vertices whose edges begin_edges lists
  std::vector<int> heap_;                     // edges added while the edges are visited (a min-heap)
  size_t next_ = 0;                           // the next of found_ to visit
  size_t moved_seen_ = 0;                     // moved_ entries whose edges were added
  int last_edge_ = -1;                        // the edge visited last
};

}  // namespace simbake
