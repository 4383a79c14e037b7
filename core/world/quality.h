// Quality figures of a world's current state: what a render of this frame would show wrong.
//
// Measured apart from the solver (every pair of bodies whose bounding spheres meet, not only
// the pairs the last broad phase kept; the cloth's edges, not only its vertices; its
// triangles against each other), so that the figures can judge the solver rather than repeat
// it. The pipeline calls this once per written frame and writes the figures beside the cache.
#pragma once

#include "world/world.h"

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

}  // namespace simbake
