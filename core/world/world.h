// The world: rigid bodies on an optional ground plane, and cloths, stepped frame by frame.
//
// The world owns the models (what each body and cloth is), their data (their state) and the
// settings, and runs the schedule; the solvers are free functions of (model, data, scratch)
// in rigid/ and cloth/, and their order is stages.h's. World::step is the scheme of
// Guendelman, Bridson and Fedkiw (2003), as the seed notes teach it: the rigid stages
// (step_bodies), then every cloth's step (cloth/cloth_step.h). Within a frame the cloths step
// at their own rate, once every few substeps and over those substeps' time (schedule.h).
// Statistics (energy, penetration, substeps) are gathered once per frame.
#pragma once

#include "cloth/cloth_step.h"
#include "contact/cloth_body_contact.h"
#include "world/cloth_coupling.h"
#include "rigid/rigid_scratch.h"
#include "world/stages.h"
#include "world/statistics.h"
#include "world/world_settings.h"

#include <array>
#include <functional>
#include <optional>
#include <vector>

namespace simbake {

class World {
 public:
  explicit World(const WorldSettings& settings = WorldSettings());

  void set_ground(const GroundDef& ground);
  const std::optional<GroundDef>& ground() const { return rigid_model_.ground; }
  // Validates and adds a body; returns its index (bodies are addressed by index)
  int add_body(const BodyDesc& desc);
  // Validates and adds a cloth, which collides with every body and the ground with its
  // friction and keeps its thickness from their surfaces; returns its index
  int add_cloth(const ClothDesc& desc);
  int cloth_count() const { return static_cast<int>(cloths_.size()); }
  const Cloth& cloth(int i) const { return cloths_[i].cloth; }
  Cloth& cloth(int i) { return cloths_[i].cloth; }
  // the edges of cloth i, (j, k) with j < k, sorted
  const std::vector<std::array<int, 2>>& cloth_edges(int i) const { return cloths_[i].contact.edges(); }
  // Attaches cloth i's attached vertices (ClothDesc::attached) to body b's surface where they
  // are now (contact/cloth_attachment.h: bound to its nearest surface point, carried with it
  // from then on; a dynamic body takes the reaction). A deforming body's surface must be set
  // first (set_deforming_frame). A cloth with attached vertices must be attached before it steps
  void attach_cloth(int i, int b);
  // Validates and adds a joint between two bodies (or a body and the world, kWorldBody);
  // returns its index
  int add_joint(const JointDesc& desc);
  int joint_count() const { return static_cast<int>(rigid_model_.joints.size()); }
  const JointState& joint_state() const { return rigid_data_.joints; }
  // Joint j's error now: the gap between its frames along what it holds (m), and the angle (rad)
  JointError joint_error(int j) const { return simbake::joint_error(rigid_model_, rigid_data_, j); }
  // Bodies a and b never collide; collision groups (rigid/collision_filter.h)
  void filter_pair(int a, int b);
  void set_collision_groups(const std::vector<std::vector<int>>& members, const std::vector<std::vector<int>>& filters);
  // Makes kinematic body i follow a key track from now on (time 0 is when the world starts)
  void set_kinematic_track(int i, KinematicTrack track);
  // Makes kinematic body i a deforming collider (contact/deforming_surface.h) whose surface
  // ends the next frame (of frame_dt s, from now) at `vertices` (its mesh's, in world
  // coordinates: the body's mesh pose must be the identity) with the level set `shape` baked
  // from them (world coordinates); the first call puts it there, still
  void set_deforming_frame(int i, const Points& vertices, SignedDistancePtr shape, double frame_dt);
  double time() const { return time_; }  // (s) simulated so far
  // (s) the last substep's length: the bodies' velocities are those of its middle along
  // gravity (the step's kick comes before its drift), their end's are v + dt g / 2
  double last_substep() const { return last_substep_; }

  // Advance one frame of length frame_dt in `substeps` equal steps, or automatic ones when
  // substeps == 0 (which, with joints and no cloth, shorten part-way through the frame when
  // a jointed body turns faster than they allow: schedule.cpp); returns the number of
  // substeps taken. `stop`, if given, is asked before
  // each substep after the first (it must be cheap: the bindings' looks at the clock and, every
  // 50 ms, at Python's signals); when it says true the frame ends there, part-way, without
  // its statistics, and the world is left at that substep. It changes nothing else
  int step_frame(double frame_dt, int substeps = 0, const std::function<bool()>& stop = nullptr);
  // One substep: the stages in order, the cloths stepped with the bodies
  void step(double dt);
  // Substeps the automatic rule picks for the next frame (a multiple of the cloth steps)
  int automatic_substeps(double frame_dt) const;
  // Cloth steps the automatic rule picks for the next frame (1 with no cloth)
  int automatic_cloth_steps(double frame_dt) const;

  int body_count() const { return rigid_model_.body_count(); }
  const RigidModel& rigid_model() const { return rigid_model_; }
  const RigidData& rigid_data() const { return rigid_data_; }
  RigidData& rigid_data() { return rigid_data_; }
  const RigidBodyDef& body_def(int i) const { return rigid_model_.defs[i]; }
  RigidBodyState body_state(int i) const { return simbake::body_state(rigid_data_, i); }
  Pose body_mesh_pose(int i) const { return simbake::body_mesh_pose(rigid_model_, rigid_data_, i); }
  const WorldSettings& settings() const { return settings_; }
  // What the steps did and what the state is now; the penetration figures are measured (over
  // the last broad phase's pairs) only when asked for, else NaN
  StepStatistics statistics(bool penetrations = true) const;
  const StageProfile& profile() const { return profile_; }
  // Deepest penetration of any sample into another body or the ground, now (m, >= 0)
  double max_penetration() const;
  bool asleep(int i) const { return rigid_data_.asleep[i] != 0; }
  double rest_time(int i) const { return rigid_data_.rest_time[i]; }  // (s) resting so far
  int sleeping_count() const;

 private:
  // one substep of the rigid bodies (every stage but the cloths')
  void step_bodies(double dt);
  void begin_cloth_step();  // records the bodies' poses the cloths' step starts from
  void blend_deforming_surfaces(double time);  // each deforming collider's level set at `time` (s)
  void step_cloths(double dt);

  WorldSettings settings_;
  RigidModel rigid_model_;                  // the bodies: defs, meshes, tracks, ground
  RigidData rigid_data_;                    // their state
  RigidScratch rigid_scratch_;              // the rigid stages' per-step scratch
  std::vector<SteppedCloth> cloths_;        // (ncloth) cloths, their state, contacts, self-collision
  ClothCoupling coupling_;                  // the bodies as the cloths' contacts see them
  double time_ = 0.0;                       // simulated time at the start of the step (s)
  double last_substep_ = 0.0;               // (s)
  StepStatistics stats_;
  StageProfile profile_;
  // the state a substep began from, while it may be taken again (step_frame)
  struct Retry {
    RigidData data;
    double time = 0.0;
    StepStatistics stats;
  } retry_;
};

}  // namespace simbake
