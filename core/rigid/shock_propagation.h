// Shock propagation (Guendelman et al. 2003, section 7): after the contact stage, the contact
// graph solved level by level from the ground up, each level resting on the frozen levels
// below (the method is at the top of shock_propagation.cpp).
#pragma once

#include "rigid/rigid_scratch.h"
#include "world/world_settings.h"

namespace simbake {

// Over the contact stage's points (scratch.contacts) and islands, with its candidates
void propagate_shocks(const RigidModel& model, RigidData& data, RigidScratch& scratch, const WorldSettings& settings);

}  // namespace simbake
