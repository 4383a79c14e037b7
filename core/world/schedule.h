// The automatic substep rule: how many substeps the next frame takes, and how many of them
// the cloths step at (the derivation is in schedule.cpp).
#pragma once

#include "cloth/cloth_step.h"
#include "levelset/deforming_surface.h"
#include "rigid/rigid_data.h"
#include "world/world_settings.h"

#include <vector>

namespace simbake {

// The substeps of a frame and the cloth steps among them (the cloths step once every
// substeps / cloth_steps substeps, over that many substeps' time)
struct FrameSchedule {
  int substeps = 1;
  int cloth_steps = 1;  // 1 with no cloth
};

// Whether anything in the world can collide: a ground, or a body with a shape (a chain of
// shapeless links cannot)
bool anything_collides(const RigidModel& model);

// The fastest turn of an awake jointed dynamic body (rad/s), 0 with none: the automatic
// substeps keep its turn per substep within WorldSettings::joint_turn
double jointed_turn_rate(const RigidModel& model, const RigidData& data);

// The automatic schedule of the frame of length frame_dt (s) that starts at `time` (s);
// `surfaces` (body index, null or missing for a body that does not deform) the deforming
// colliders' surfaces over that frame
FrameSchedule frame_schedule(const RigidModel& model, const RigidData& data, const std::vector<SteppedCloth>& cloths,
                             const WorldSettings& settings, double time, double frame_dt,
                             const std::vector<const DeformingSurface*>& surfaces = {});

}  // namespace simbake
