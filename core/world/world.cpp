// The world: building it, and the schedule of a frame and a substep. The stages are the
// solvers' (stages.h lists them with their files).
#include "world/world.h"

#include "math/threads.h"
#include "rigid/broad_phase.h"
#include "rigid/collision_filter.h"
#include "rigid/collisions.h"
#include "rigid/contacts.h"
#include "rigid/impulse_stage.h"
#include "rigid/integration.h"
#include "rigid/joints.h"
#include "rigid/kinematic_bodies.h"
#include "rigid/shock_propagation.h"
#include "rigid/sleeping.h"
#include "world/cloth_coupling.h"
#include "world/schedule.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace simbake {

namespace {
// (m, rad) a joint error a step ends at above this: its Newton solve did not converge
constexpr double kUnconvergedJoints = 1e-6;
// a substep after which a jointed body turns faster than this many joint_turns per step is
// taken again in shorter ones
constexpr double kRetakeTurn = 1.25;
}  // namespace

World::World(const WorldSettings& settings) : settings_(settings) { check_settings(settings); }

void World::set_ground(const GroundDef& ground) {
  check_ground(ground);
  rigid_model_.ground = ground;
}

int World::add_body(const BodyDesc& desc) {
  check_body(desc);
  rigid_model_.defs.push_back(make_body_def(desc));
  rigid_model_.meshes.push_back({desc.mesh_vertices, desc.mesh_triangles});
  rigid_model_.tracks.emplace_back();
  rigid_model_.body_joints.emplace_back();
  rigid_model_.groups.push_back(0);
  add_body_state(desc, rigid_model_.defs.back(), rigid_data_);
  add_body_scratch(rigid_model_, rigid_data_, rigid_scratch_);
  return body_count() - 1;
}

int World::add_joint(const JointDesc& desc) {
  check_joint(desc, body_count());
  const int j = joint_count();
  rigid_model_.joints.push_back(make_joint_def(rigid_model_, desc));
  for (int body : {desc.body0, desc.body1}) {
    if (body != kWorldBody) rigid_model_.body_joints[body].push_back(j);
  }
  JointState& state = rigid_data_.joints;
  state.enabled.push_back(desc.enabled ? 1 : 0);
  state.broke_at.push_back(std::nan(""));
  state.force.push_back(Vec3::Zero());
  state.torque.push_back(Vec3::Zero());
  return j;
}

void World::filter_pair(int a, int b) { add_filtered_pair(rigid_model_, a, b); }

void World::set_collision_groups(const std::vector<std::vector<int>>& members,
                                 const std::vector<std::vector<int>>& filters) {
  simbake::set_collision_groups(rigid_model_, members, filters);
}

int World::add_cloth(const ClothDesc& desc) {
  cloths_.emplace_back(desc);
  return cloth_count() - 1;
}

void World::attach_cloth(int i, int b) {
  if (!(i >= 0 && i < cloth_count())) throw std::invalid_argument("attach_cloth: cloth " + std::to_string(i) + " does not exist");
  if (!(b >= 0 && b < body_count())) throw std::invalid_argument("attach_cloth: body " + std::to_string(b) + " does not exist");
  SteppedCloth& cloth = cloths_[i];
  std::vector<int> vertices;
  const std::vector<char>& attached = cloth.cloth.model().attached;
  for (int k = 0; k < cloth.cloth.vertex_count(); ++k) {
    if (attached[k]) vertices.push_back(k);
  }
  if (vertices.empty()) throw std::invalid_argument("attach_cloth: cloth " + std::to_string(i) + " has no attached vertices");
  describe_bodies(rigid_model_, rigid_data_, coupling_, time_);
  cloth.attachment.emplace(cloth.cloth, vertices, b, coupling_.bodies);
}

void World::set_kinematic_track(int i, KinematicTrack track) {
  if (!(i >= 0 && i < body_count() && rigid_model_.defs[i].kinematic)) {
    throw std::invalid_argument("only kinematic bodies follow keys");
  }
  rigid_model_.tracks[i] = std::move(track);
  move_kinematic_bodies(rigid_model_, rigid_data_, time_, 0.0);
}

int World::automatic_substeps(double frame_dt) const {
  return frame_schedule(rigid_model_, rigid_data_, cloths_, settings_, time_, frame_dt, rigid_scratch_.surfaces).substeps;
}

int World::automatic_cloth_steps(double frame_dt) const {
  return frame_schedule(rigid_model_, rigid_data_, cloths_, settings_, time_, frame_dt, rigid_scratch_.surfaces).cloth_steps;
}

int World::step_frame(double frame_dt, int substeps, const std::function<bool()>& stop) {
  if (!(frame_dt > 0.0 && std::isfinite(frame_dt))) throw std::invalid_argument("frame_dt must be > 0");
  // the cloths step once every `group` substeps, over the group's time (a fixed substep
  // count steps them every substep)
  const FrameSchedule schedule = substeps > 0 ? FrameSchedule{substeps, substeps}
                                             : frame_schedule(rigid_model_, rigid_data_, cloths_, settings_, time_, frame_dt, rigid_scratch_.surfaces);
  int n = std::min(schedule.substeps, settings_.max_substeps);
  double dt = frame_dt / n;
  const int cloth_steps = std::min(schedule.cloth_steps, n);
  const int group = n % cloth_steps == 0 ? n / cloth_steps : 1;
  // automatic substeps of a world with joints and no cloth shorten within the frame when a
  // jointed body turns faster than they allow (schedule.cpp)
  const bool replan = substeps == 0 && cloths_.empty() && !rigid_model_.joints.empty();
  bool stopped = false;
  int taken = n;
  on_threads(settings_.threads, [&] {
    for (int k = 0; k < n && stats_.finite; ++k) {
      // (asked between substeps: a signal ends a long frame within a substep; the state after
      // each substep is the same whether or not anyone asks)
      if (k > 0 && stop && stop()) {
        stopped = true;
        taken = k;
        break;
      }
      if (replan) retry_ = {rigid_data_, time_, stats_};
      if (k % group == 0) begin_cloth_step();
      blend_deforming_surfaces(time_ + dt);
      step_bodies(dt);
      if ((k + 1) % group == 0) {
        StageTimer timer(profile_, Stage::kCloths);
        step_cloths(group * dt);
      }
      // a NaN is caught at once and reported, never stepped on
      if (!state_finite(rigid_data_, cloths_)) stats_.finite = false;
      if (replan && n < settings_.max_substeps) {
        const double turn = jointed_turn_rate(rigid_model_, rigid_data_);
        const bool unconverged = rigid_scratch_.joints.error > kUnconvergedJoints;
        // the substeps from `from` on, as many as the fastest turn asks and at least
        // `at_least` times as many (within max_substeps), the frame's time shared among them
        const auto spread_rest = [&](int from, double at_least) {
          const int left = n - from;
          const double wanted = std::max(std::ceil(left * dt * turn / settings_.joint_turn), at_least * left);
          if (!(wanted > left)) return;
          const int steps = std::min(static_cast<int>(wanted), settings_.max_substeps - from);
          dt *= static_cast<double>(left) / steps;
          n = from + steps;
        };
        // a substep whose joints' solve did not converge, or that left a jointed body turning
        // much faster than its step allows (a whip: the tip's spin doubles within a substep),
        // is taken again, shorter, from where it began: such a step is what gains energy
        if (unconverged || turn * dt > kRetakeTurn * settings_.joint_turn) {
          rigid_data_ = retry_.data;
          time_ = retry_.time;
          stats_ = retry_.stats;
          spread_rest(k, 2.0);
          --k;
          continue;
        }
        spread_rest(k + 1, 0.0);
      }
    }
  });
  if (stopped) return taken;
  if (stats_.finite) {
    StageTimer timer(profile_, Stage::kJoints);
    project_joint_velocities(rigid_model_, rigid_data_, rigid_scratch_.joints, dt);
  }
  {
    StageTimer timer(profile_, Stage::kStatistics);
    gather_statistics(rigid_model_, rigid_data_, cloths_, settings_, stats_);
  }
  return n;
}

void World::step(double dt) {
  begin_cloth_step();
  blend_deforming_surfaces(time_ + dt);
  step_bodies(dt);
  StageTimer timer(profile_, Stage::kCloths);
  step_cloths(dt);
}

void World::step_bodies(double dt) {
  const RigidModel& model = rigid_model_;
  RigidData& data = rigid_data_;
  RigidScratch& scratch = rigid_scratch_;
  { StageTimer timer(profile_, Stage::kKinematicBodies); move_kinematic_bodies(model, data, time_, dt); }
  // every dynamic body asleep and no kinematic body moving: no pair, no contact, nothing moves
  bool quiet = true;
  for (int i = 0; i < body_count() && quiet; ++i) {
    quiet = model.defs[i].kinematic ? !moving_kinematic(model, data, i) : data.asleep[i] != 0;
  }
  if (quiet) {
    scratch.pairs.clear();
    scratch.contacts.clear();
    time_ += dt;
    last_substep_ = dt;
    ++stats_.substeps;
    return;
  }
  scratch.speculative = settings_.speculative_contacts && cloths_.empty();
  // with no ground and no body something can touch (a chain of shapeless links) nothing
  // collides: no pair, no contact, and the stages that find them have nothing to do
  const bool collidable = anything_collides(model);
  if (collidable) {
    { StageTimer timer(profile_, Stage::kBroadPhase); broad_phase(model, data, scratch, settings_, dt); }
    { StageTimer timer(profile_, Stage::kCollisions); resolve_collisions(model, data, scratch, settings_, dt, stats_.substeps); }
  } else {
    scratch.pairs.clear();
    scratch.contacts.clear();
  }
  { StageTimer timer(profile_, Stage::kVelocities); update_velocities(model, data, settings_, dt); }
  if (collidable) {
    { StageTimer timer(profile_, Stage::kContacts); resolve_contacts(model, data, scratch, settings_, dt); }
    { StageTimer timer(profile_, Stage::kShockPropagation); propagate_shocks(model, data, scratch, settings_); }
  }
  { StageTimer timer(profile_, Stage::kJoints); solve_joints(model, data, scratch.joints, dt, time_ + dt); }
  if (!model.joints.empty() && !scratch.contacts.empty()) {
    // the joints coupled bodies the contacts saw apart (a glued pair landing: the upper one's
    // momentum now pushes the lower into the ground): contacts once more, then the joints
    { StageTimer timer(profile_, Stage::kContacts); resolve_contacts(model, data, scratch, settings_, dt); }
    { StageTimer timer(profile_, Stage::kShockPropagation); propagate_shocks(model, data, scratch, settings_); }
    { StageTimer timer(profile_, Stage::kJoints); solve_joints(model, data, scratch.joints, dt, time_ + dt); }
  }
  { StageTimer timer(profile_, Stage::kPositions); update_positions(model, data, scratch, settings_, dt); }
  { StageTimer timer(profile_, Stage::kSleeping); update_sleeping(model, data, scratch, settings_, dt); }
  stats_.impulses += scratch.impulses;
  scratch.impulses = 0;
  time_ += dt;
  last_substep_ = dt;
  ++stats_.substeps;
}

void World::begin_cloth_step() {
  if (cloths_.empty()) return;
  record_start_poses(rigid_model_, rigid_data_, coupling_, time_);
}

void World::step_cloths(double dt) {
  if (!cloths_.empty()) ++stats_.cloth_steps;
  const ClothStepSettings cloth_settings{settings_.gravity, settings_.cloth_contacts_in_solve};
  for (SteppedCloth& cloth : cloths_) {
    if (!cloth.attachment && std::find(cloth.cloth.model().attached.begin(), cloth.cloth.model().attached.end(), 1) !=
                                 cloth.cloth.model().attached.end()) {
      throw std::logic_error("a cloth with attached vertices steps only once attached to a body (World::attach_cloth)");
    }
    // the bodies as the contacts see them, posed as they are now (only the pinches at the
    // end of this cloth's step move them); what the contacts did to them, applied after
    describe_bodies(rigid_model_, rigid_data_, coupling_, time_);
    if (step_cloth(cloth, coupling_.bodies, dt, cloth_settings, profile_, stats_.self_collision)) ++stats_.cloth_gave;
    apply_contact_results(coupling_.bodies, rigid_model_, rigid_data_);
  }
}

void World::set_deforming_frame(int i, const Points& vertices, SignedDistancePtr shape, double frame_dt) {
  RigidBodyDef& def = rigid_model_.defs[i];
  if (!def.kinematic) throw std::invalid_argument("only a kinematic body can deform");
  if (!shape) throw std::invalid_argument("a deforming body needs its level set");
  if (vertices.rows() != rigid_model_.meshes[i].vertices.rows()) {
    throw std::invalid_argument("a deforming body keeps its mesh's " + std::to_string(rigid_model_.meshes[i].vertices.rows()) +
                                " vertices, got " + std::to_string(vertices.rows()));
  }
  const Pose pose = body_mesh_pose(i);
  if (!pose.translation.isZero(1e-12) || !pose.rotation.isIdentity(1e-12)) {
    throw std::invalid_argument("a deforming body's mesh pose must be the identity (its vertices are in world coordinates)");
  }
  std::vector<std::shared_ptr<DeformingSurface>>& surfaces = coupling_.surfaces;
  surfaces.resize(body_count());
  if (!surfaces[i]) {
    for (const SteppedCloth& cloth : cloths_) {
      if (cloth.attachment && cloth.attachment->body() == i) {
        throw std::invalid_argument("a body a cloth is attached to becomes deforming only before the attachment");
      }
    }
    surfaces[i] = std::make_shared<DeformingSurface>(vertices, shape, time_);
  } else {
    surfaces[i]->set_frame(vertices, shape, time_, frame_dt);
  }
  rigid_scratch_.surfaces.resize(body_count(), nullptr);
  rigid_scratch_.surfaces[i] = surfaces[i].get();
  def.deforming = true;
  def.shape = surfaces[i]->shape_at(0.0);
  // the broad phases' and the contacts' reach: the surface anywhere over the frame
  def.bounding_radius = surfaces[i]->reach(rigid_data_.x[i]);
}

void World::blend_deforming_surfaces(double time) {
  for (size_t b = 0; b < coupling_.surfaces.size(); ++b) {
    if (coupling_.surfaces[b]) rigid_model_.defs[b].shape = coupling_.surfaces[b]->shape_at(coupling_.surfaces[b]->blend(time));
  }
}

StepStatistics World::statistics(bool penetrations) const {
  StepStatistics s = stats_;
  if (penetrations) on_threads(settings_.threads, [&] { measure_penetrations(rigid_model_, rigid_data_, rigid_scratch_.pairs, cloths_, s); });
  return s;
}

double World::max_penetration() const {
  return simbake::max_penetration(rigid_model_, rigid_data_, rigid_scratch_.pairs);
}

int World::sleeping_count() const { return simbake::sleeping_count(rigid_data_); }

}  // namespace simbake
