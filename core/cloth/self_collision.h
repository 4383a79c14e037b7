// Cloth against itself over one step: a cloth that starts free of self-intersection ends the
// step free of it, whatever folds or heaps.
//
// Bridson, Fedkiw and Anderson, "Robust treatment of collisions, contact and friction for
// cloth animation" (SIGGRAPH 2002), on the velocities v that carry the positions x to
// x + dt v (the step's last word on the cloth's velocities, after internal forces, bodies and
// strain limiting):
//   1. repulsions: every point-triangle and edge-edge pair closer than the thickness h at x
//      gets an inelastic impulse that stops its approach and, when still closer than h, a
//      push apart of at most 0.1 (h - d) / dt, with Coulomb friction on the relative slip;
//   2. collisions: continuous detection over [x, x + dt v]: the times at which a point and a
//      triangle (or two edges) are coplanar are the roots of a cubic; at each, the pair is a
//      collision if its distance is within a small tolerance; an inelastic impulse stops the
//      approach; a few Gauss-Seidel passes;
//   3. rigid impact zones (Provot 1997), the fail-safe: vertices of the collisions still left
//      are merged into zones, each zone moved rigidly (its linear and angular momentum kept),
//      and detection repeated until none is left; a zone holding a pinned vertex stays still.
// Impulses are shared by the pair's vertices in proportion to their weights and inverse
// masses (pinned vertices have none), so momentum is conserved.
//
// Candidates come from a uniform grid over the boxes swept by triangles and edges over the
// step (each entered once; the cell as large as the boxes), padded by a margin of a quarter edge: the list is kept
// for the step's later passes while no vertex's motion over the step has changed by more than
// the margin since (so it still holds every pair that can meet), and found again otherwise.
// A pair's cubic is skipped when its Bernstein coefficients on [0, 1] share one sign (no root,
// exactly). Pairs are tested in parallel in fixed chunks; impulses are applied in order, so
// the result is the same at any thread count. The cost is near linear in the vertex count.
#pragma once

#include "math/types.h"

#include <Eigen/Core>

#include <array>
#include <vector>

namespace simbake {

struct SelfCollisionSettings {
  double thickness = 0.005;   // h (m): pairs closer than this are pushed apart
  double friction = 0.3;      // Coulomb coefficient of the cloth on itself
  int collision_passes = 4;   // impulse passes of continuous detection before impact zones
  int zone_iterations = 50;   // impact-zone rounds before the last resort (the cloth holds still)
};

struct SelfCollisionStatistics {
  long long repulsions = 0;    // proximity impulses applied
  long long collisions = 0;    // continuous-detection impulses applied
  long long zone_rounds = 0;   // impact-zone rounds taken
  long long zone_vertices = 0; // vertices moved rigidly in impact zones
  long long stills = 0;        // steps in which the last resort held the cloth still
  long long searches = 0;      // times the candidate pairs were found
  long long candidates = 0;    // candidate pairs found, in all searches
};

class SelfCollision {
 public:
  SelfCollision(const Triangles& triangles, int vertex_count);

  // Changes v so that x + s dt v, s in [0, 1], never passes a layer through another: the
  // three parts below in turn. inverse_mass (n): 0 for pinned vertices, which never move.
  void resolve(const Points& x, Points& v, const Eigen::VectorXd& inverse_mass, double dt,
               const SelfCollisionSettings& settings, SelfCollisionStatistics& stats);

  // 1. repulsions between pairs closer than the thickness at x
  void repel(const Points& x, Points& v, const Eigen::VectorXd& inverse_mass, double dt,
             const SelfCollisionSettings& settings, SelfCollisionStatistics& stats);
  // 2. `passes` passes of collision impulses; true when the last pass found none left
  bool collide(const Points& x, Points& v, const Eigen::VectorXd& inverse_mass, double dt,
               const SelfCollisionSettings& settings, SelfCollisionStatistics& stats, int passes);
  // 3. rigid impact zones until nothing collides (or, at last, the cloth held still)
  void impact_zones(const Points& x, Points& v, const Eigen::VectorXd& inverse_mass, double dt,
                    const SelfCollisionSettings& settings, SelfCollisionStatistics& stats);
  // (n) 1 for the vertices the last impact_zones moved rigidly
  const std::vector<char>& zone_vertices() const { return in_zone_; }

  // A contact of the continuous detection: a point against a triangle (vertices a = the point,
  // then the triangle's) or an edge against an edge (a0 a1, then b0 b1), at a time in [0, 1]
  // of the step, with barycentric weights (positive for the first side, negative for the
  // second) and the unit normal from the second side towards the first
  struct Contact {
    int vertex[4];
    double weight[4];
    Vec3 normal;
    double distance;  // (m) at the start of the step (repulsion) or 0 (collision)
  };

 private:
  class Grid;
  // candidate pairs (vertex, triangle) and (edge, edge), found at positions x with motion
  // dt v; valid while every vertex's motion stays within `margin` of that
  struct Candidates {
    std::vector<std::pair<int, int>> point_triangle, edge_edge;
    Points x, motion;
    double pad = -1.0, margin = 0.0;
  };
  Candidates candidates_;
  std::vector<char> in_zone_;
  Triangles triangles_;
  std::vector<std::array<int, 2>> edges_;
  int vertex_count_;

  void proximity_contacts(const Points& x, const Points& v, double dt, double h, std::vector<Contact>& out,
                          SelfCollisionStatistics& stats);
  void collision_contacts(const Points& x, const Points& v, double dt, double tolerance, std::vector<Contact>& out,
                          SelfCollisionStatistics& stats);
  const Candidates& candidates(const Points& x, const Points& v, double dt, double pad, SelfCollisionStatistics& stats);
};

}  // namespace simbake
