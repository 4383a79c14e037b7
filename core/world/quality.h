// Quality figures of a world's current state: what a render of this frame would show wrong.
//
// Measured apart from the solver (every pair of bodies whose bounding spheres meet, not only
// the pairs the last broad phase kept; the cloth's edges, not only its vertices; its
// triangles against each other), so that the figures can judge the solver rather than repeat
// it. The pipeline calls this once per written frame and writes the figures beside the cache.
#pragma once

#include "world/world.h"

#include <cmath>
#include <cstdint>
#include <unordered_map>
#include <vector>

namespace simbake {

// The deepest point of one thing inside another
struct PenetrationFigure {
  double depth = 0.0;  // (m), >= 0; past the other's surface (a cloth's thickness not counted)
  int a = -1;          // the body (or cloth) that is inside; -1 when nothing is
  int b = -1;          // the body it is inside; -1 for the ground
};

struct ClothQuality {
  double max_strain = 0.0;               // largest edge strain |l| / L - 1
  long long self_intersections = 0;      // pairs of triangles sharing no vertex that cross; -1 when
                                         // not counted (more candidate pairs than kPairTestBudget:
                                         // a cloth crumpled into a few cells)
  PenetrationFigure vertex_penetration;  // deepest vertex inside a body or the ground (a = this cloth)
  PenetrationFigure edge_penetration;    // deepest point along an edge (its eighths), likewise
};

struct FrameQuality {
  PenetrationFigure body_penetration;  // deepest surface sample of a dynamic body inside another
                                       // body or the ground (pairs of two kinematic bodies and
                                       // kinematic bodies against the ground are not counted)
  std::vector<ClothQuality> cloths;    // (ncloth)
};

FrameQuality measure_quality(const World& world);

// Each part on its own
PenetrationFigure body_penetration(const World& world);
ClothQuality cloth_quality(const World& world, int cloth);

// What bounds how deep one body's samples can be in anything, from its def alone
struct BodyExtent {
  const void* shape = nullptr;       // the shape and samples it was taken from, by address
  const void* samples_at = nullptr;
  Eigen::Index sample_count = 0;
  double samples = 0.0;              // largest |sample| in mesh coordinates (m)
  double solid = INFINITY;           // the solid lies within this of the mesh origin (m); a
                                     // grid's phi is no exact distance: no bound
  bool is_box = false;               // a box shape (BoxDistance) ...
  bool samples_in_box = false;       // ... whose samples all lie on or in it
  Vec3 half = Vec3::Zero();          // its half edge lengths (m)
};
BodyExtent body_extent(const RigidBodyDef& def);

// What the last calls measured, frame to frame: each candidate's depth with the two bodies'
// poses then. A candidate whose bodies are where they were has that depth again; else its
// depth now is at most that depth plus how far any of its samples can have moved through the
// other body's field (at most the field's Lipschitz constant per metre): a bound that passes
// over the many pairs of a pile that barely moved and stayed shallow.
struct DepthMemo {
  struct Known {
    PenetrationFigure depth;                // the candidate's figure when measured
    int a = -1, b = -1;                     // the candidate's bodies in its order then
    Pose pose_a, pose_b;                    // their mesh poses then
    const void* shapes[4] = {};             // their shapes and samples then, by address
  };
  std::unordered_map<std::uint64_t, Known> last, next;  // by pair (lower, higher body; the ground last)
};
// body_penetration with each body's extent (extents[i] of body i) already known, and with
// `memo` (if given) what the calls before it measured: the same figure
PenetrationFigure body_penetration(const World& world, const std::vector<BodyExtent>& extents,
                                   DepthMemo* memo = nullptr);

// The body figure by testing every sample of every pair whose bounding spheres meet: what
// body_penetration returns, bit for bit (it skips only what cannot be the deepest); the
// reference of the tests
PenetrationFigure body_penetration_every_sample(const World& world);

// The figures frame after frame, measuring only what can have changed: the body figure is
// kept while no body has moved (every body's centre of mass and orientation the same bits,
// the same shapes, the joints' flags the same), as in a pile gone to sleep, and each pair's
// depth is bounded by what was measured before (DepthMemo). The same figures as
// measure_quality, bit for bit.
class QualityMeter {
 public:
  FrameQuality measure(const World& world);

 private:
  FrameQuality measure_on_arena(const World& world);
  bool same_bodies_and_ground(const World& world) const;  // as when last measured (by count)
  bool unchanged(const World& world) const;  // since the body figure was last measured
  void remember(const World& world);

  std::vector<BodyExtent> extents_;        // (nbody)

  std::vector<double> poses_;              // (nbody x 7) x and q when last measured
  std::vector<const void*> shapes_;        // (nbody x 2) shape and samples, by address
  std::vector<char> joints_enabled_;       // (njoint)
  double ground_ = 0.0;                    // its height (m); NaN: no ground
  PenetrationFigure body_;
  DepthMemo memo_;
  bool measured_ = false;
};

}  // namespace simbake
