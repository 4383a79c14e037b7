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
//      and detection repeated until none is left; a zone holding a pinned vertex stays still,
//      one holding attached vertices moves with their attachment.
// Impulses are shared by the pair's vertices in proportion to their weights and inverse
// masses (pinned vertices have none), so momentum is conserved.
//
// Impulses are applied in an order that does not depend on how the pairs were found:
// repulsions closest first, collisions earliest first (ties by vertex index), so the result is
// the same at any thread count and with any broad phase.
//
// Candidates come from boxes kept in a frame that translates with the vertices' median motion
// (a cloth falling as one keeps its boxes): a vertex's box holds its start and end of the step,
// grown by a margin (a tenth of the mean edge); a point's, a triangle's or an edge's box holds
// its vertices' boxes, grown by half the thickness, so two items that come within the
// thickness have meeting boxes. The boxes are gathered in a tree of patches of the surface
// (cloth/patch_tree.h; one over the cloth's triangles, one over the obstacles'), each vertex
// and edge a member of one leaf (its first triangle's). The pairs are those of leaves whose
// boxes meet, found by descending the tree into itself (Volino and Magnenat-Thalmann 1994),
// except inside a patch that is flat over the step: a patch whose triangles keep their normals
// within 84 degrees of one direction and whose boundary stays a star around an inner vertex
// is mapped one to one onto a plane, so none of its points meets another (the tree's header
// gives the argument; PatchTree.FlatPatchesNeverMeetThemselves checks it by brute force). A
// smooth sheet is flat in large patches, so only its bent places and where layers meet cost
// pairs (a uniform grid over the boxes would find every neighbouring pair). Like the near
// pairs, a pair inside a flat patch is not repelled either: it is in-plane, the membrane's
// business. The pairs are kept, across passes and steps, while every vertex's start and end
// stay in its box, and each flat patch is tested again over every pass whose velocities
// changed on it: one no longer flat gives its pairs then. A vertex that leaves its box gets a
// new one and only the pairs around it are found again (the tree's boxes above it refitted); all
// pairs are found again when an eighth of the vertices leave their boxes at once.
// Each candidate's distance d at the step's start is measured once (where the gap between its
// two sides' boxes is at least h, the gap stands for it until a finer bound is needed); it gives
// the repulsions and spares most pairs the cubic: distances are 1-Lipschitz in each vertex, so
// over the step a pair's distance falls by at most its relative motion R (the largest motion of
// the second side's vertices relative to the first side's first vertex, plus the first side's
// own spread for two edges), and a pair with d - R above the tolerance cannot collide. A pair
// found clear in a collision pass is clear again in a later one if none of its four vertices'
// velocities changed in between. The cubic itself is skipped when its Bernstein coefficients on
// [0, 1] share one sign (no root, exactly). Pairs are tested in parallel in fixed chunks. The
// cost grows with the vertex count times the candidates a vertex has.
//
// Near pairs. When the thickness nears the edge length, most candidates are pairs of
// neighbouring elements of a smooth sheet (most of them once the thickness is more than half
// an edge), which can neither collide nor come closer than h across the sheet there. Two kinds, each around an interior vertex q (one whose triangles close
// around it), its pivot: a point p next to q and a triangle of q's without p; the edge
// across a triangle of q's from q and an edge of q outside that triangle. They are kept out of
// the broad phase and are candidates in a pass only where q's triangles are not flat over
// the step: flat means one direction a with n(s) . a >= 0.1 |n(s)| for the normal n(s) of
// each of q's triangles over the whole step (n(s) is quadratic in s; its three Bernstein
// coefficients bound it). Then the projection along a maps q's triangles one to one onto
// the plane around q (each keeps its orientation, and they wind once around q because the
// sheet starts free of crossings), so a point on one of q's edges cannot be inside another
// triangle of q's, nor an edge across one of them cross another of q's edges: neither pair
// meets during the step. A near pair in a flat place is in-plane, and its repulsion would
// only resist compression, which is the membrane's business. A smooth sheet's pivots are
// nearly all flat, so few near pairs are candidates in any step.
// SelfCollision.NearPairsOfAFlatPivotNeverMeet checks the argument by brute force.
//
// Obstacles. Bodies the cloth must not pass through (a box's edge, a pole, a keyed mover) can
// join as obstacles: their triangles are added to the cloth's, their vertices numbered after
// the cloth's, of infinite mass (inverse mass 0, so impulses move only the cloth's side) and
// moving with the obstacle over the step (x + s dt v: the caller gives each vertex its start
// and its velocity to its end). A pair of a cloth point and an obstacle triangle, an
// obstacle point and a cloth triangle, or a cloth edge and an obstacle edge is then a
// candidate like the cloth's own pairs, so that the continuous test and the impact zones
// keep the cloth from passing through an obstacle, and an obstacle's corner or edge from
// passing through the cloth, over the step (Bridson et al. treat bodies as such infinite-mass
// members of their collision handling). Pairs within one obstacle are never candidates, and
// pairs with an obstacle are not repelled: the cloth's contacts with the bodies hold it at
// the thickness from them, with their friction. An impact zone holding an obstacle's
// vertices moves with that obstacle (ObstacleMotion), unless that would carry one of its
// vertices into the still surface it rests on (a keyed box pressing the cloth into the
// ground): then the surface holds the zone and the obstacle passes through the cloth there.
// Vertices the obstacles have let in (SelfCollisionSettings::yielding: inside one, or a
// cloth stretched past what it can hold) are not kept out of them.
//
// Bounded work. Whatever the cloth does (a keyed body pressing it into the ground or through
// its pins, a blown-up step), a step's self-collision costs at most a budget, and when the
// budget runs out it says so and the caller has a fallback that keeps the guarantee above:
//   - candidate pairs held at once: SelfCollisionSettings::candidate_budget a vertex (512).
//     The searches stop as soon as they hold more (a blown-up 32 x 32 sheet had all 6.5
//     million pairs of its triangles and edges as candidates, 13 searches a step, 100 s);
//   - pairs visited by the step's collision passes, in all: pass_budget a vertex (16,384;
//     a step makes at most 12 + 8 + 3 x 54 passes: the world's rounds, the zones' 50 each);
//   - impact-zone rounds of a call: zone_iterations (50), as before.
// The first two stop the step's self-collision (over_budget(); its later calls do nothing)
// and the caller holds the cloth still for the step; the third holds it still at once (the
// last resort). Both are counted (SelfCollisionStatistics: over_budget, stills), with the
// largest figures seen (candidate_peak, pass_peak, zone_round_peak), for the pipeline's QA
// to warn about. None of the shipped scenes comes near them: their peaks are 142 candidate
// pairs a vertex, 3,456 pairs visited a vertex and step, 16 zone rounds (the heap).
#pragma once

#include "cloth/patch_tree.h"
#include "geometry/mesh.h"
#include "math/types.h"

#include <Eigen/Core>

#include <array>
#include <memory>
#include <vector>

namespace simbake {

// An obstacle's motion over the step as a velocity field: a point at x at the step's start
// moves at A x + c (m/s), on a line to where the obstacle's end pose takes it. For an
// obstacle posed by (R0, t0) at the start and (R1, t1) at the end, with R = R1 R0^T:
// A = (R - I) / dt and c = (t1 - R t0) / dt
struct ObstacleMotion {
  Mat3 A = Mat3::Zero();
  Vec3 c = Vec3::Zero();
};

struct SelfCollisionSettings {
  double thickness = 0.0;     // h (m): pairs closer than this are pushed apart (the cloth's)
  double friction = 0.0;      // Coulomb coefficient of the cloth on itself (the cloth's)
  int collision_passes = 4;   // impulse passes of continuous detection before impact zones
  int zone_iterations = 50;   // impact-zone rounds before the last resort (the cloth holds still)
  // (n) or null: for each vertex resting on a still surface this step (the ground, a static
  // body), the normal of that surface (any length), else zero. An impulse (a repulsion or a
  // collision) that would push such a vertex into its surface leaves it where it is and
  // moves the pair's other vertices instead: the surface holds it, as a pin would; a pair
  // whose vertices are all held so, or whose free ones would move by more than 4x the
  // change (a light corner left alone), is left to the impact zones. An impact zone whose rigid
  // motion would take one of its vertices into its surface holds still. Without this, layers
  // landing on a heap share their impulses with its bottom layer as if nothing were under
  // it, and self-collision, which has the last word in a step, ends steps with vertices under
  // the ground (by the impulses, and by the zones' rigid motion)
  const std::vector<Vec3>* support = nullptr;
  // (obstacles) or null: each obstacle's motion over the step (the impact zones that hold an
  // obstacle's vertices move with it; without it, they hold still)
  const std::vector<ObstacleMotion>* obstacle_motion = nullptr;
  // (cloth vertices) or null: 1 for the cloth's attached vertices (ClothDesc::attached), and
  // their attachment's motion over the step: the impact zones that hold them move with it
  // (without it, they hold still, as at a pin)
  const std::vector<char>* attached = nullptr;
  const ObstacleMotion* attachment_motion = nullptr;
  // (n) or null: 1 for the cloth's vertices that the obstacles no longer keep out (let in,
  // they pass through the cloth there: contact/cloth_obstacles.h, yielding): pairs of an
  // obstacle and an item with such a vertex are not tested
  const std::vector<char>* yielding = nullptr;
  // Budgets (see "Bounded work" at the top of this file): zone_iterations (above) bounds the
  // impact-zone rounds of a call; these bound the pairs. The most a step may hold at once
  // (the broad phase's and the near pairs) is candidate_budget, and the most its collision
  // passes may visit in all is pass_budget, both per vertex (the cloth's and the obstacles',
  // at least budget_vertices of them: a small cloth may take what a 64 x 64 one may)
  double candidate_budget = 512.0;  // pairs a vertex (the heap: 142 at most; 16 KiB a vertex at 512)
  double pass_budget = 16384.0;     // pairs visited a vertex and step (the heap: 3,456 at most)
  int budget_vertices = 4096;
};

struct SelfCollisionStatistics {
  long long repulsions = 0;    // proximity impulses applied
  long long collisions = 0;    // continuous-detection impulses applied
  long long zone_rounds = 0;   // impact-zone rounds taken
  long long zone_vertices = 0; // vertices moved rigidly in impact zones
  long long stills = 0;        // steps in which the last resort held the cloth still
  long long searches = 0;      // times the candidate pairs were found
  long long candidates = 0;    // candidate pairs found, in all searches
  long long updates = 0;       // times the pairs around the vertices that left their boxes were found again
  long long tests = 0;         // candidate pairs put through the continuous test (d - R at most the tolerance)
  long long near_pairs = 0;    // near pairs made candidates (where the sheet is not flat), in all steps
  long long over_budget = 0;   // steps whose self-collision ran out of a budget (the cloth held still)
  long long yields = 0;        // impact zones held still where their obstacle would have carried them
                               // into the still surface under them (the obstacle passes through)
  long long let_in = 0;        // steps in which the obstacles let cloth vertices in (yielding: the
                               // cloth world counts them, contact/cloth_obstacles.h)
  // the largest of their kind seen so far (maxima, not sums): candidate pairs held at once,
  // pairs the collision passes of one step visited, impact-zone rounds of one call
  long long candidate_peak = 0;
  long long pass_peak = 0;
  long long zone_round_peak = 0;
};

class SelfCollision {
 public:
  // the cloth's triangles and vertex count, and the obstacles' meshes (their triangles; their
  // vertex counts, the positions being the caller's at each call). Every call's x, v and
  // inverse_mass then hold the cloth's vertices and, after them, each obstacle's in turn;
  // the obstacles' inverse masses are 0
  SelfCollision(const Triangles& triangles, int vertex_count, const std::vector<TriangleMesh>& obstacles = {});
  ~SelfCollision();
  SelfCollision(SelfCollision&&) noexcept;
  SelfCollision& operator=(SelfCollision&&) noexcept;

  // A new step: its budgets (SelfCollisionSettings) start again. The caller of the three parts
  // below calls it before each step (resolve does); until then a step that went over budget
  // stays so
  void begin_step();
  // true once this step ran out of a budget: the three parts then do nothing, and the caller
  // holds the cloth still for the step (its velocities zero: it stays free of crossings)
  bool over_budget() const { return over_budget_; }

  // Changes v so that x + s dt v, s in [0, 1], never passes a layer through another: the
  // three parts below in turn (a new step: begin_step first). inverse_mass (n): 0 for pinned
  // vertices, which never move.
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
  // the vertices of the cloth and of the obstacles
  int vertex_count() const { return vertex_count_; }
  // (n) 1 for the vertices the last impact_zones moved rigidly
  const std::vector<char>& zone_vertices() const { return in_zone_; }
  // impulses (n x 3, N s) on the vertices of the last impact zones, each zone taking those on
  // its vertices as one rigid body (its momentum and angular momentum gain them; a zone holding
  // a pinned vertex stays still). For what the strain limiter pushed against zones it held still.
  void push_zones(const Points& x, Points& v, const Eigen::VectorXd& inverse_mass,
                  const SelfCollisionSettings& settings, const Points& impulse) const;

  // A contact of the continuous detection: a point against a triangle (vertices a = the point,
  // then the triangle's) or an edge against an edge (a0 a1, then b0 b1), at a time in [0, 1]
  // of the step, with barycentric weights (positive for the first side, negative for the
  // second) and the unit normal from the second side towards the first
  struct Contact {
    int vertex[4];
    double weight[4];
    Vec3 normal;
    double distance;  // (m) at the start of the step (repulsion) or 0 (collision)
    double time = 0.0;  // of the step, in [0, 1]: when the collision happens (0 for a repulsion)
  };

 private:
  // a candidate pair: four vertices (a point and a triangle's three, or two edges' two), its
  // distance at the step's start (m, NaN until measured; where `exact` is false, only a lower
  // bound: the gap between the two sides' boxes, at least h) and the collision pass after
  // which the continuous test last found it clear (-1: not since it was measured)
  struct Pair {
    std::array<int, 4> vertex;
    double distance;
    int clear;
    bool exact;
  };
  // the candidate pairs, pairs[0] points against triangles and pairs[1] edges against edges,
  // and the boxes (see the top of this file; vertex_boxes without the pad)
  struct Candidates {
    std::array<std::vector<Pair>, 2> pairs;
    std::vector<Box3> vertex_boxes, point_boxes, triangle_boxes, edge_boxes;
    double pad = -1.0, margin = 0.0;  // (m)
    // the boxes are in a frame that moves with the cloth: a translation, by `frame` (m) at
    // this step's start and by frame_step (m) more over the step (the vertices' median motion)
    Vec3 frame = Vec3::Zero(), frame_step = Vec3::Zero();
  };
  // the step's start positions x (n x 3) and the repulsion contacts there: the pairs closer
  // than the thickness h (those touching, closer than 1e-9 h, with their normal still to be
  // turned against the approach)
  struct Start {
    Points x;
    double h = -1.0;
    bool measured = false;  // every pair's distance is known, and the contacts
    std::vector<Contact> proximity;
  };
  // the collision passes so far: a pair found clear after pass p is clear again at a later
  // pass if none of its vertices' velocities has changed since (and the step, dt and the
  // tolerance are the same)
  struct Passes {
    int pass = 0;
    int first = 0;             // passes before this one count for nothing
    std::vector<int> changed;  // (n) the last pass before which each vertex's velocity changed
    Points velocity;           // (n x 3) the velocities at the last pass (m/s)
    double dt = 0.0, tolerance = 0.0;
  };
  // the near pairs (see the top of this file) of each pivot, built once, and those that are
  // candidates in this step
  struct Near {
    std::vector<char> pivot;                                // (n) 1 for an interior vertex
    std::array<std::vector<int>, 2> first;                  // (n + 1) per kind: pivot q's at [first[q], first[q + 1])
    std::array<std::vector<std::array<int, 2>>, 2> items;   // (point, triangle) | (edge, edge), per kind
    std::vector<int> edge_first, edge_opposite;             // each edge's triangles' third vertices
    std::vector<char> active;                               // (n) the pivots whose pairs are candidates this step
    std::array<std::vector<Pair>, 2> pairs;                 // those candidates
    std::vector<char> check;                                // scratch: the pivots whose flatness is looked at again
  };
  // each triangle's normal over the step, n(s) = (e1 + s d1) x (e2 + s d2), by its Bernstein
  // coefficients on [0, 1] (n(s) is a convex combination of them, so n(s) . a is at least
  // their least and |n(s)| at most their largest): for the near pairs' pivots and the trees'
  // flat patches. The velocities and dt they are of, and which changed at the last call
  struct Normals {
    std::vector<std::array<Vec3, 3>> normal;  // (triangles)
    std::vector<double> largest;              // (triangles) the largest of their norms
    Points velocity;
    double dt = 0.0;
    bool all = true;                          // every triangle changed (a new step)
    std::vector<char> changed;                // (triangles)
  };
  // the broad phase's trees (cloth/patch_tree.h), [0] over the cloth's triangles and [1] over
  // the obstacles', with each leaf's points and edges (a vertex is a point of the leaf of its
  // first triangle, an edge of its first triangle's) and, in the cloth's, the flat node at
  // which the last full search stopped above each leaf (-1: none)
  struct Tree {
    PatchTree tree;
    std::vector<int> point_first, points, edge_first, edges, cull;
  };
  // where an item is at home: its tree and leaf
  struct Home {
    int tree = -1, leaf = -1;
  };
  Candidates candidates_;
  std::array<Tree, 2> trees_;
  bool trees_built_ = false;
  std::vector<Home> point_home_, edge_home_;  // (vertices), (edges)
  std::vector<int> orphans_;  // vertices of no triangle: points tried against every triangle
  int cloth_triangles_ = 0;
  Near near_;
  Normals normals_;
  Start start_;
  Passes passes_;
  std::vector<char> in_zone_;
  std::vector<int> zone_parent_;  // (n) the last impact zones: union-find parents (a root is its own)
  // this step's budgets (begin_step): pairs the collision passes visited, whether one ran out;
  // and the most candidate pairs a search may hold (start sets it; the searches stop past it)
  long long pass_work_ = 0;
  bool over_budget_ = false;
  long long pair_limit_ = 0;
  bool full(const std::array<std::vector<Pair>, 2>& pairs) const {
    return static_cast<long long>(pairs[0].size() + pairs[1].size()) > pair_limit_;
  }
  // this step's self-collision out of budget: counted, its candidates let go
  void stop_over_budget(SelfCollisionStatistics& stats);
  Triangles triangles_;
  std::vector<std::array<int, 2>> edges_;
  int vertex_count_;    // the cloth's and the obstacles'
  int cloth_vertices_;  // the cloth's: vertices [0, cloth_vertices_)
  std::vector<int> obstacle_of_;  // (obstacle vertices) the obstacle each belongs to
  // each vertex's triangles and edges: those of vertex k at [first[k], first[k + 1])
  std::vector<int> triangle_first_, vertex_triangles_, edge_first_, vertex_edges_;

  bool obstacle(int k) const { return k >= cloth_vertices_; }
  // whether point k and triangle t, or edges e and f, are candidates when their boxes meet:
  // not neighbours, not a near pair, not both of the obstacles
  bool point_triangle_candidate(int k, int t) const;
  bool edge_candidate(int e, int f) const;
  Pair point_triangle_pair(int k, int t) const;  // point k against triangle t, not yet measured
  Pair edge_pair(int e, int f) const;             // edges e and f (the lower index first), not yet measured
  // the candidate lists: 0, 1 the broad phase's (points against triangles, edges against
  // edges), 2, 3 this step's near pairs of the same kinds
  std::vector<Pair>& pair_list(int list);
  // the last impact zones' vertices, ascending, at each zone's root (others empty)
  std::vector<std::vector<int>> zone_members() const;
  void build_near();
  int edge_index(int a, int b) const;  // the edge joining vertices a and b, or -1
  int point_pivot(int k, int t) const;  // the pivot of point k and triangle t (not on it) if near, else -1
  int edge_pivot(int e, int f) const;   // the pivot of edges e and f (no shared vertex) if near, else -1
  // the near pairs of the pivots whose triangles are not flat over the step (normals_, which
  // bound_normals set first), made candidates (at a new step, only those)
  void activate_near(bool new_step, SelfCollisionStatistics& stats);
  // normals_ for the step from x to x + dt v: at a new step all, else those of the triangles
  // whose vertices' velocities changed since the last call
  void bound_normals(const Points& x, const Points& v, double dt, bool new_step);
  // the flat nodes the broad phase stopped at, where a triangle's normal changed: those no
  // longer flat over this step give their pairs (found below them, as a full search would)
  void check_flat(const Points& x, const Points& v, double dt, SelfCollisionStatistics& stats);
  // the near pairs measured again at the next measure: all, or those with a vertex `moving`
  void forget_near(const std::vector<char>* moving);
  // true when it searched all pairs again
  bool update_candidates(const Points& x, const Points& v, double dt, double pad, SelfCollisionStatistics& stats);
  Box3 vertex_box(const Points& x, const Points& v, double dt, int k) const;
  void build_trees(const Points& x);
  Home triangle_home(int t) const;
  // the node of tree `tree` that a query from `home` skips: the flat node above it (-1: none)
  int skipped(const Home& home, int tree) const;
  // the candidates of point k against the triangles of a leaf of `tree` whose boxes meet its, added to out
  void point_against_leaf(int k, const Tree& tree, int leaf, std::vector<Pair>& out) const;
  // the candidates among the items of leaf a of tree i and leaf b of tree j (a leaf with
  // itself: each pair once), added to out
  void leaf_pairs(int i, int a, int j, int b, std::array<std::vector<Pair>, 2>& out) const;
  // the candidates within node n of the cloth's tree (none where it is flat: its leaves
  // remember it), and between node a of tree i and node b of tree j
  void self_pairs(int n, const Points& x, const Points& v, double dt, std::array<std::vector<Pair>, 2>& out);
  void cross_pairs(int i, int a, int j, int b, std::array<std::vector<Pair>, 2>& out) const;
  void search_all(const Points& x, const Points& v, double dt, double pad, SelfCollisionStatistics& stats);
  void search_moved(const Points& x, const Points& v, double dt, const std::vector<int>& moved,
                    SelfCollisionStatistics& stats);
  const Start& start(const Points& x, const Points& v, double dt, const SelfCollisionSettings& settings,
                     SelfCollisionStatistics& stats);
  // the distances of the pairs not measured yet (all: of every pair, each also no longer
  // clear nor exact, as at a new step)
  void measure(const Points& x, double h, bool all);
  void collision_contacts(const Points& x, const Points& v, double dt, const SelfCollisionSettings& settings,
                          std::vector<Contact>& out, SelfCollisionStatistics& stats);
  // the earliest contact of one candidate over the step into `found`, if any (the pair marked
  // clear otherwise); true when it took the continuous test
  bool earliest_contact(int kind, Pair& pair, const Points& x, const Points& v, double dt, double tolerance,
                        std::vector<Contact>& found) const;
};

}  // namespace simbake
