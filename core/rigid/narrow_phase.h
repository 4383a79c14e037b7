// The narrow phase of the impulse stages (the method is at the top of narrow_phase.cpp): per
// pair the broad phase kept, the points of each body inside the other (or the ground) at the
// candidates, and how a point found once follows its bodies' candidates.
#pragma once

#include "rigid/box_contact.h"
#include "rigid/rigid_scratch.h"
#include "world/world_settings.h"

namespace simbake {

// of the thinner body's thickness: deeper, the level set's normal no longer points the way out
inline constexpr double kTrustedDepth = 0.25;
// (m) closer than this to a surface is touching, not penetrating
inline constexpr double kTouching = 1e-9;

// Every pair's points (scratch.pair_points, one list per pair of scratch.pairs), both
// directions; with `speculative` those closer than a margin too; with `reuse`, a pair whose
// bodies took no collision impulse keeps the list the collision stage found. In parallel over
// the pairs, the same result on any number of threads
void find_pair_penetrations(const RigidModel& model, const RigidData& data, RigidScratch& scratch,
                            const WorldSettings& settings, bool speculative, bool reuse);

// Moves a point with its body's candidate and takes the other body's normal and distance there
void refresh_contact(const RigidModel& model, const RigidData& data, const RigidScratch& scratch, Penetration& p);

// Body i as an oriented box at the pose, when its shape is a box
bool body_box(const RigidModel& model, int i, const Pose& pose, OrientedBox& out);

}  // namespace simbake
