// The broad phase: the pairs of bodies (and bodies and the ground) that may touch over the
// step; sleeping islands an awake body touches are woken here (the method is at the top of
// broad_phase.cpp).
#pragma once

#include "rigid/rigid_scratch.h"
#include "world/world_settings.h"

namespace simbake {

// scratch.pairs for a step of dt, sorted by index, each with its combined friction and
// restitution; sleeping islands touched by an awake body or a moving kinematic body are woken
void broad_phase(const RigidModel& model, RigidData& data, RigidScratch& scratch, const WorldSettings& settings,
                 double dt);

// A pair's friction and restitution from the two bodies' (or a body's and the ground's)
double combine_friction(double a, double b);
double combine_restitution(double a, double b);

}  // namespace simbake
