// The stages of a world step, in order of execution, and the profile that times them.
//
// A substep (World::step_bodies, then the cloths' step every few substeps):
//   kinematic_bodies   keyed bodies placed on their tracks        rigid/kinematic_bodies.h
//   broad_phase        pairs that may touch; sleepers woken       rigid/broad_phase.h
//   collisions         elastic impulses at the candidates         rigid/collisions.h
//   velocities         gravity                                    rigid/integration.h
//   contacts           inelastic impulses, average velocities     rigid/contacts.h
//   shock_propagation  the contact graph level by level           rigid/shock_propagation.h
//   joints             joints held at the end of the step         rigid/joints.h
//   positions          x += dt v, torque-free rotation            rigid/integration.h
//   sleeping           islands at rest put to sleep               rigid/sleeping.h
//   cloths             every cloth's step, of which:              cloth/cloth_step.h
//     cloth_forces         internal forces and the velocity update    cloth/integrators.h
//     cloth_contacts       contacts with bodies and the ground        contact/cloth_body_contact.h
//     cloth_strain         strain limiting                            cloth/strain_limiting.h
//     cloth_self_collision self-collision                             cloth/self_collision.h
// and once a frame:
//   statistics         energy, penetration, strain                world/statistics.h
#pragma once

#include <array>
#include <chrono>

namespace simbake {

enum class Stage : int {
  kKinematicBodies,
  kBroadPhase,
  kCollisions,
  kVelocities,
  kContacts,
  kShockPropagation,
  kJoints,
  kPositions,
  kSleeping,
  kCloths,
  kClothForces,
  kClothContacts,
  kClothStrain,
  kClothSelfCollision,
  kStatistics,
  kCount
};

inline constexpr int kStageCount = static_cast<int>(Stage::kCount);

// Each stage's name, as the profile reports it (Python's World.profile() keys)
inline constexpr std::array<const char*, kStageCount> kStageNames = {
    "kinematic_bodies", "broad_phase", "collisions", "velocities", "contacts", "shock_propagation", "joints", "positions",
    "sleeping", "cloths", "cloth_forces", "cloth_contacts", "cloth_strain", "cloth_self_collision", "statistics"};
static_assert(kStageNames[kStageCount - 1] != nullptr, "a name for every stage");

// Wall seconds spent in each stage since the world was built (a cloth sub-stage's time is
// also in `cloths`)
struct StageProfile {
  std::array<double, kStageCount> seconds{};

  double& operator[](Stage stage) { return seconds[static_cast<int>(stage)]; }
  double operator[](Stage stage) const { return seconds[static_cast<int>(stage)]; }
};

// Adds the wall time of its scope to a stage's entry of a profile
class StageTimer {
 public:
  StageTimer(StageProfile& profile, Stage stage) : total_(profile[stage]), start_(std::chrono::steady_clock::now()) {}
  ~StageTimer() { total_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count(); }
  StageTimer(const StageTimer&) = delete;
  StageTimer& operator=(const StageTimer&) = delete;

 private:
  double& total_;
  std::chrono::steady_clock::time_point start_;
};

}  // namespace simbake
