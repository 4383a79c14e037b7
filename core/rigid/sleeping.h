// Sleeping: bodies at rest cost nothing until something touches them (the method is at the
// top of sleeping.cpp).
#pragma once

#include "rigid/rigid_scratch.h"
#include "world/world_settings.h"

namespace simbake {

// After a step of dt: each awake dynamic body's rest time, and the islands (through this
// step's contact points, scratch.contacts) whose every body has rested for sleep_time put to
// sleep, their velocities zeroed
void update_sleeping(const RigidModel& model, RigidData& data, const RigidScratch& scratch,
                     const WorldSettings& settings, double dt);

// Wakes every sleeping body of body i's island
void wake_island(const RigidModel& model, RigidData& data, int i);

// The bodies asleep now
int sleeping_count(const RigidData& data);

}  // namespace simbake
