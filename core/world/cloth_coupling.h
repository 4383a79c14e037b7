// Bodies and cloths meet here: the bodies described to a cloth's contacts
// (contact/contact_bodies.h) when its step begins, and what those contacts did to the bodies
// (impulses, woken islands, the pinches' displacements) applied to the bodies' state after
// it, in the order the contacts did it.
#pragma once

#include "contact/contact_bodies.h"
#include "rigid/rigid_data.h"

#include <memory>
#include <vector>

namespace simbake {

// What the coupling keeps over the cloths' step
struct ClothCoupling {
  std::vector<Pose> start_poses;  // (nbody) each body's mesh pose when the cloths' step began
  double start_time = 0.0;        // (s) when the cloths' step began
  // (nbody) a deforming collider's surface over the frame (the world sets it), else null
  std::vector<std::shared_ptr<DeformingSurface>> surfaces;
  ContactBodies bodies;           // the bodies as the cloth being stepped sees them (scratch)
};

// Each body's mesh pose now, at `time` (s): where the cloths' step starts from
// (ContactBody::start_pose, and a deforming surface's ContactBody::surface_start)
void record_start_poses(const RigidModel& model, const RigidData& data, ClothCoupling& coupling, double time);

// The bodies and the ground as a cloth's contacts see them now, at `time` (s), into coupling.bodies
void describe_bodies(const RigidModel& model, const RigidData& data, ClothCoupling& coupling, double time);

// What the contacts recorded in `bodies`, applied to the bodies' state
void apply_contact_results(const ContactBodies& bodies, const RigidModel& model, RigidData& data);

}  // namespace simbake
