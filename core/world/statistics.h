// The world's statistics: what the steps did (substeps, impulses, solver work, in total) and
// what the state is now (energy, penetration, strain), gathered once a frame.
#pragma once

#include "cloth/cloth_step.h"
#include "rigid/rigid_scratch.h"
#include "world/world_settings.h"

#include <cmath>
#include <vector>

namespace simbake {

struct StepStatistics {
  long long substeps = 0;          // substeps taken since the world was built
  long long cloth_steps = 0;       // cloth steps taken since the world was built
  long long cloth_solver_iterations = 0;  // conjugate-gradient iterations of the cloths' implicit steps, in all
  double cloth_solver_seconds = 0.0;      // their CPU time (preconditioner updates and CG), in all (s)
  double max_penetration = NAN;    // deepest sample inside another body or the ground (m), now;
                                   // NaN unless asked for (measure_penetrations)
  double kinetic_energy = 0.0;     // (J), now, bodies and cloths
  double elastic_energy = 0.0;     // cloths' stretch and bending energy (J), now
  double cloth_penetration = NAN;  // deepest cloth vertex inside a body or the ground, past its
                                   // surface (m), now, the thickness not counted; NaN likewise
  double max_cloth_strain = 0.0;   // largest edge strain of any cloth, last frame
  double potential_energy = 0.0;   // gravity, -m g.x (J), now
  long long impulses = 0;          // collision and contact impulses applied, in total
  SelfCollisionStatistics self_collision;  // the cloths' self-collision work, in total
  long long cloth_gave = 0;        // cloth steps in which a cloth was stretched past what its strain
                                   // limit can hold (cloth/cloth_step.cpp, kGiveStrain), in total
  bool finite = true;              // false once any state went NaN or infinite
};

// The figures of the state now into `stats` (energies, strain, solver totals), once a frame
void gather_statistics(const RigidModel& model, const RigidData& data, const std::vector<SteppedCloth>& cloths,
                       const WorldSettings& settings, StepStatistics& stats);

// The penetration figures of the state now into `stats`, only for a caller that asks: a bake
// with QA has its own independent measure. `pairs` are the last broad phase's, the only ones
// that can touch
void measure_penetrations(const RigidModel& model, const RigidData& data, const std::vector<BodyPair>& pairs,
                          const std::vector<SteppedCloth>& cloths, StepStatistics& stats);

// Deepest penetration of any sample into another body or the ground, now, over the pairs (m, >= 0)
double max_penetration(const RigidModel& model, const RigidData& data, const std::vector<BodyPair>& pairs);

// Whether every body's and every cloth's state is finite
bool state_finite(const RigidData& data, const std::vector<SteppedCloth>& cloths);

}  // namespace simbake
