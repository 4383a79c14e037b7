// One cloth's step as a recipe of named sub-stages (cloth_step.cpp), over one cloth as the
// world steps it: the cloth itself (model, state, solver scratch), its contacts with the
// bodies and the ground, its self-collision and the kinematic bodies that join it as
// obstacles.
#pragma once

#include "cloth/cloth.h"
#include "cloth/self_collision.h"
#include "contact/cloth_attachment.h"
#include "contact/cloth_body_contact.h"
#include "contact/cloth_obstacles.h"
#include "contact/contact_bodies.h"
#include "world/stages.h"

#include <optional>

namespace simbake {

struct SteppedCloth {
  explicit SteppedCloth(const ClothDesc& desc) : cloth(desc), contact(cloth) {
    if (cloth.model().self_collision) self.emplace(cloth.triangles(), cloth.vertex_count());
  }

  Cloth cloth;                        // model, state (x, v) and the implicit solver's scratch
  ClothBodyContact contact;           // contacts with bodies and ground: their state and scratch
  std::optional<SelfCollision> self;  // self-collision, when on
  ClothObstacles obstacles;           // the bodies its self-collision keeps it from
  std::optional<ClothAttachment> attachment;  // its attached vertices' body, when it has them
};

struct ClothStepSettings {
  Vec3 gravity = Vec3::Zero();     // (m/s^2)
  bool contacts_in_solve = true;   // WorldSettings::cloth_contacts_in_solve
};

// One step of dt (s) of the cloth against the bodies (contact/contact_bodies.h: what the
// contacts, and the attachment's reaction, do to the bodies is recorded there, for the world
// to apply), its attached vertices carried by their body; each sub-stage timed
// into `profile`, self-collision's work counted into `stats`. True when the cloth gave way
// this step (stretched past what its strain limit can hold: cloth_step.cpp, kGiveStrain)
bool step_cloth(SteppedCloth& cloth, ContactBodies& bodies, double dt, const ClothStepSettings& settings,
                StageProfile& profile, SelfCollisionStatistics& stats);

}  // namespace simbake
