// The collision stage (elastic): bodies advanced over the step with forces to candidate
// states, and impulses with restitution where their candidates interpenetrate (the method is
// at the top of collisions.cpp).
#pragma once

#include "rigid/rigid_scratch.h"
#include "world/world_settings.h"

namespace simbake {

// Resolves the collisions of the pairs in scratch.pairs over a step of dt; `step` (the substeps
// taken so far) seeds the order in which each sweep visits the pairs. Leaves scratch.collided
// (the bodies that took an impulse) and the pairs' points for the contact stage to reuse
void resolve_collisions(const RigidModel& model, RigidData& data, RigidScratch& scratch, const WorldSettings& settings,
                        double dt, long long step);

}  // namespace simbake
