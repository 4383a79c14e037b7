// Which pairs of bodies never collide: bodies held by an enabled joint that does not let
// them (collision_enabled false, as PhysX and UsdPhysics default), filtered pairs
// (PhysicsFilteredPairsAPI) and collision groups (PhysicsCollisionGroup) that filter each
// other. The broad phase drops such pairs before any narrow phase.
#pragma once

#include "rigid/rigid_data.h"

#include <vector>

namespace simbake {

// Whether bodies a and b (a != b, neither the ground) are kept from colliding now
bool collision_filtered(const RigidModel& model, const RigidData& data, int a, int b);

// Adds the pair (a, b) to the pairs that never collide
void add_filtered_pair(RigidModel& model, int a, int b);

// Collision groups: members[g] the bodies of group g, filters[g] the groups group g does not
// collide with (a pair is filtered when either's group filters the other's); at most 64
void set_collision_groups(RigidModel& model, const std::vector<std::vector<int>>& members,
                          const std::vector<std::vector<int>>& filters);

}  // namespace simbake
