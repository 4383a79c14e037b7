// The world's settings: the rigid solver's sweeps and tolerances, the automatic substep rule's
// limits, the worker threads. One home: the Python bindings construct this struct by keyword
// and read its defaults from here (bindings/module.cpp), and World's constructor checks it.
#pragma once

#include "math/types.h"

namespace simbake {

// the most worker threads a world takes (WorldSettings::threads)
inline constexpr int kMaxThreads = 1024;

struct WorldSettings {
  Vec3 gravity = Vec3(0.0, -9.81, 0.0);  // (m/s^2)
  int collision_sweeps = 5;              // elastic sweeps over all pairs (the notes: 3-5)
  int contact_sweeps = 6;                // inelastic sweeps over all pairs (at most)
  int shock_sweeps = 10;                 // sweeps per level of shock propagation (at most; more
                                         // hold a tall tower a little straighter, at a cost in piles)
  double sleep_speed = 0.01;             // (m/s) a body whose points stray less than
  double sleep_time = 0.5;               // (s) sleep_speed * sleep_time / 2 for sleep_time
                                         // may sleep; sleep_time 0 disables sleeping
  double penetration_slop = 2e-4;        // (m) deeper contacts are pushed apart ...
  double penetration_recovery = 0.2;     // ... at this fraction of (depth - slop) per step
  double max_recovery_speed = 0.5;       // (m/s) ... but never faster than this
  double contact_tolerance = 1e-6;       // (m/s) contact sweeps stop once no impulse
                                         // changes a point velocity by more than this
  bool speculative_contacts = true;      // the contact stage also takes points not yet inside,
                                         // closer than a margin (see contact_margin), and lets
                                         // each close its gap within the step but no more
                                         // (worlds without cloths only)
  bool box_contacts = true;              // two boxes meet by their exact contact (separating
                                         // axes and clipping, rigid/box_contact.h), not by
                                         // samples against the level set
  double max_substep = 1.0 / 120.0;      // (s) longest automatic substep
  double cloth_contact_substep = 1.0 / 240.0;  // (s) longest substep while a dynamic body may
                                         // touch a cloth (see world/schedule.cpp)
  double bounce_substep = 1.0 / 240.0;   // (s) longest substep while a body may bounce: an awake
                                         // dynamic body and any restitution above 0 (see
                                         // world/schedule.cpp)
  bool cloth_contacts_in_solve = true;   // cloth vertices resting on a surface are held there
                                         // inside the implicit solve (contact/cloth_body_contact.cpp,
                                         // contact_constraints), not only stopped after it
  double cloth_max_substep = 1.0 / 120.0; // (s) longest automatic cloth step: cloths step at
                                         // their own, coarser rate (every few substeps)
  double travel_fraction = 0.2;          // automatic substeps: per substep no body travels
                                         // more than this fraction of its thickness
  double joint_turn = 0.1;               // (rad) automatic substeps: per substep no jointed
                                         // body turns more than this, checked again after
                                         // every substep of a frame; a substep that ends
                                         // turning 1.25 times this, or whose joints' solve did
                                         // not converge, is taken again, shorter (a whip).
                                         // Fewer, longer steps lose more of a mechanism's
                                         // energy, and from about 0.2 some gain
                                         // (benchmarks/rigid/joint_turn.py)
  int max_substeps = 4096;               // per frame, automatic or not
  int threads = 0;                       // worker threads, in [0, kMaxThreads]; 0 = all cores.
                                         // Results are identical for any count.
};

// Throws std::invalid_argument naming the first setting out of its range
void check_settings(const WorldSettings& settings);

}  // namespace simbake
