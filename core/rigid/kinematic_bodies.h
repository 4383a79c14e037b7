// Keyed kinematic bodies placed on their tracks (rigid/kinematic_track.h) at the start of each
// step, moving at the constant velocity and spin that reach the track's pose at the step's end.
#pragma once

#include "rigid/rigid_data.h"

namespace simbake {

// Each keyed body on its track at time `time` (s), with the velocity and spin that carry it to
// the track's pose at time + dt exactly (update_positions moves it); dt 0 puts it at rest there
void move_kinematic_bodies(const RigidModel& model, RigidData& data, double time, double dt);

}  // namespace simbake
