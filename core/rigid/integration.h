// The rigid bodies' velocity and position updates, the two stages around the contact stage
// (DESIGN.md, "The world step", stages 3 and 5).
#pragma once

#include "rigid/rigid_scratch.h"
#include "world/world_settings.h"

namespace simbake {

// Velocities: gravity on every awake dynamic body (no torque: it acts at the centre of mass)
void update_velocities(const RigidModel& model, RigidData& data, const WorldSettings& settings, double dt);

// Positions: x += dt v and the torque-free rotation with the final L (what the contact
// stage's average velocities assumed), through each awake body's candidate
void update_positions(const RigidModel& model, RigidData& data, RigidScratch& scratch, const WorldSettings& settings,
                      double dt);

}  // namespace simbake
