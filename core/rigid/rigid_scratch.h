// What the rigid stages work with during one step and keep only so that a step allocates
// nothing: candidate end-of-step states, the pairs the broad phase kept, the contact points,
// islands, shock propagation's levels. Nothing here outlives the step it was computed in
// (the rigid state is rigid_data.h's).
#pragma once

#include "levelset/deforming_surface.h"
#include "rigid/contact_points.h"
#include "rigid/islands.h"
#include "rigid/joints.h"
#include "rigid/overlapping_pairs.h"
#include "rigid/rigid_data.h"

#include <cstdint>
#include <utility>
#include <vector>

namespace simbake {

// A pair of bodies the broad phase kept for this step
struct BodyPair {
  int a, b;                      // b may be kGround
  double friction, restitution;  // combined (see combine_friction in rigid/broad_phase.cpp)
};

// A contact point of the contact stage, found when the stage begins
struct ContactPoint {
  Penetration point;
  double friction;
  Vec3 total = Vec3::Zero();      // impulse given to body a so far this stage (N s)
  Mat3 k_a = Mat3::Zero();        // K of body a and of body b at the point, from the
  Mat3 k_b = Mat3::Zero();        // lever arms when found (they move < 1 mm in a step)
  std::uint64_t seen_a = ~0ull;   // versions of a and b when last evaluated: while both
  std::uint64_t seen_b = ~0ull;   // stay the same, evaluating again would change nothing
  bool apart = false;             // a speculative contact: outside when the stage began; it
                                  // does not join its bodies for sleeping nor into the groups
                                  // shock propagation may send back (it does level them)
};

// Shock propagation's scratch (rigid/shock_propagation.h)
struct ShockScratch {
  std::vector<Vec3> v_before, l_before;     // (nbody) velocities before the levels
  std::vector<double> speed_before;         // (nbody) fastest point speed before (m/s)
  std::vector<int> neighbour_start;         // (nbody + 1) contact graph: body i's neighbours
  std::vector<int> neighbours;              // are neighbours[start[i] .. start[i + 1])
  std::vector<int> order;                   // connected bodies by level (breadth first)
  std::vector<int> contact_level;           // (ncontact) level of the upper body, -1 when
                                            // not connected to the ground or a kinematic body
  std::vector<int> group;                   // (nbody) union-find of contact groups
  std::vector<char> thrown;                 // (nbody) group roots thrown off by the levels
};

struct RigidScratch {
  // the impulse stage under way (rigid/impulse_stage.h)
  double dt = 0.0;                          // current substep (s)
  bool candidates_with_forces = false;      // collision stage: candidates include gravity
  bool average_velocities = false;          // contact stage: omega is the average velocity
  bool speculative = false;                 // this step takes speculative contacts (the setting,
                                            // and no cloth in the world)
  std::vector<Vec3> candidate_x;            // (nbody x 3) candidate end-of-step centres of mass (m)
  std::vector<Quat> candidate_q;            // (nbody x 4) and orientations
  std::vector<Vec3> candidate_v;            // (nbody x 3) and velocities (m/s)
  std::vector<Pose> candidate_poses;        // (nbody) mesh poses of the candidates
  // (nbody) or empty: a deforming collider's surface (its points' velocities), else null
  std::vector<const DeformingSurface*> surfaces;
  std::vector<Vec3> omega;                  // (nbody x 3) angular velocity the current impulse
                                            // stage uses at points (rad/s, world)
  std::vector<Mat3> inverse_inertia;        // (nbody x 3 x 3) world I^-1 at the start-of-step orientation
  std::vector<char> stale;                  // (nbody) candidate behind the latest impulse
  std::vector<std::uint64_t> version;       // (nbody) bumped whenever v, L or the candidate change
  std::vector<char> frozen;                 // (nbody) immovable for now (shock propagation)
  std::vector<int> level;                   // (nbody) contact-graph distance from the ground or
                                            // a kinematic body; -1 when not connected
  // the broad phase (rigid/broad_phase.h)
  std::vector<Box3> boxes;                  // (nbody) box over the step (m)
  std::vector<std::pair<int, int>> overlaps;  // overlapping boxes this step
  GridScratch grid;                         // reused by overlapping_pairs
  std::vector<BodyPair> pairs;              // pairs kept this step
  // the narrow phase and the impulse stages
  std::vector<std::vector<Penetration>> pair_points;  // (npair) points inside (and near), per pair
  std::vector<char> single_test;            // (npair) the collision stage tested the pair once
  std::vector<std::uint64_t> collision_versions;  // (nbody) versions when the collision sweeps began
  std::vector<char> collided;               // (nbody) took a collision impulse this step
  std::vector<ContactPoint> contacts;       // contact points of this step's contact stage
  IslandScratch islands;                    // this step's islands of the impulse stage under way
  ImpulseLog log;                           // the serial stages' impulses
  ShockScratch shock;                       // reused by propagate_shocks
  JointScratch joints;                      // the joints stage's components and rows
  std::vector<int> body_scratch;            // (nbody) reused by the stages
  long long impulses = 0;                   // impulses applied since the world last collected them
};

// Grows the per-body arrays by the body just added (its candidate is its state)
void add_body_scratch(const RigidModel& model, const RigidData& data, RigidScratch& scratch);

}  // namespace simbake
