// The contact stage (inelastic), after Guendelman, Bridson and Fedkiw 2003 and the seed notes:
// the points inside (and, speculative, near) when the stage begins, swept with average
// velocities until no impulse changes anything (the method is at the top of contacts.cpp).
#pragma once

#include "rigid/rigid_scratch.h"
#include "world/world_settings.h"

namespace simbake {

// Finds the contact points (scratch.contacts) and resolves them over a step of dt, island by
// island in parallel
void resolve_contacts(const RigidModel& model, RigidData& data, RigidScratch& scratch, const WorldSettings& settings,
                      double dt);

// One projected Gauss-Seidel update of a contact point's total impulse this stage, the change
// applied to its bodies; false when nothing changed (also shock propagation's update)
bool apply_contact_impulse(const RigidModel& model, RigidData& data, RigidScratch& scratch,
                           const WorldSettings& settings, ContactPoint& contact, ImpulseLog& log);

}  // namespace simbake
