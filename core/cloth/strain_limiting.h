// Strain limiting (and enforced buckling): impulses along over-stretched (and, per the
// compression mode, over-compressed) edges so that the candidates x + dt v respect their
// bounds (the method is at the top of strain_limiting.cpp).
#pragma once

#include "cloth/cloth_data.h"
#include "cloth/cloth_model.h"

#include <vector>

namespace simbake {

// Sweeps over the edges until every edge is within its bound, and with `global` the rest
// solved for all edges at once
void limit_strain(const ClothModel& model, ClothData& data, double dt, bool global);

// The same (global) with the vertices marked in `held` (n) held still as if pinned, for this
// call; returns the impulses (n x 3, N s) the held vertices would have taken (their edges'
// pushes against them, which the held ones absorb: what momentum the call did not keep)
Points limit_strain_holding(const ClothModel& model, ClothData& data, double dt, const std::vector<char>& held);

// The largest edge strain |l| / L - 1 at the candidate positions x + dt v (0 at the least)
double candidate_strain(const ClothModel& model, const ClothData& data, double dt);

}  // namespace simbake
