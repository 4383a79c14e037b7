// The world: rigid bodies on an optional ground plane, stepped frame by frame.
//
// World::step(dt) is the scheme of Guendelman, Bridson and Fedkiw (2003), as the seed notes
// teach it, as a list of named stages (see step() in world.cpp):
//   move_kinematic_bodies  keyed kinematic bodies placed on their tracks, with the velocity
//                      that carries them to the next step's key pose
//   broad_phase        pairs whose bounding boxes over the step overlap (and ground pairs)
//   resolve_collisions elastic impulses with restitution at the deepest non-separating
//                      point, from start-of-step velocities, candidates advanced with forces
//   update_velocities  gravity
//   resolve_contacts   inelastic impulses at every penetrating point, with average
//                      velocities defined exactly as update_positions moves the bodies; each
//                      point's total impulse over the stage obeys the Coulomb cone; then
//                      shock propagation: the contact graph solved level by level from the
//                      ground up, each level resting on the frozen levels below
//   update_positions   x += dt v; q by the torque-free rotation with L fixed
//   step_cloths        per cloth: internal forces and velocity update, collisions with every
//                      body's level set and the ground (contact/cloth_body_contact.h:
//                      thickness, Coulomb friction on the relative velocity, equal and
//                      opposite impulses on dynamic bodies),
//                      strain limiting and compression impulses, collisions again, positions.
//                      Within a frame the cloths step at their own rate, once every few
//                      substeps and over those substeps' time (see step_frame)
// Statistics (energy, penetration, substeps) are gathered once per frame.
#pragma once

#include "cloth/cloth.h"
#include "cloth/self_collision.h"
#include "contact/cloth_body_contact.h"
#include "contact/cloth_obstacles.h"
#include "geometry/mass_properties.h"
#include "geometry/mesh.h"
#include "rigid/box_contact.h"
#include "rigid/contact_points.h"
#include "rigid/islands.h"
#include "rigid/overlapping_pairs.h"
#include "rigid/kinematic_track.h"
#include "rigid/rigid_body.h"

#include <array>
#include <cstdint>
#include <functional>
#include <optional>
#include <vector>

namespace simbake {

struct WorldSettings {
  Vec3 gravity = Vec3(0.0, -9.81, 0.0);  // (m/s^2)
  int collision_sweeps = 5;              // elastic sweeps over all pairs (the notes: 3-5)
  int contact_sweeps = 6;                // inelastic sweeps over all pairs (at most; was 10)
  int shock_sweeps = 10;                 // sweeps per level of shock propagation (at most; was
                                         // 20). Fewer: the 1000-box piles 1.2x faster and no
                                         // deeper; the tower of 10 drifts 1.3 mm, not 0.4
                                         // (benchmarks/results/rigid_speed.md)
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
  double max_substep = 1.0 / 120.0;      // (s) longest automatic substep (1/240 before
                                         // speculative and exact box contacts)
  double cloth_contact_substep = 1.0 / 240.0;  // (s) longest substep while a dynamic body may
                                         // touch a cloth (see frame_schedule)
  double bounce_substep = 1.0 / 240.0;   // (s) longest substep while a body may bounce: an awake
                                         // dynamic body and any restitution above 0 (see
                                         // frame_schedule)
  bool cloth_contacts_in_solve = true;   // cloth vertices resting on a surface are held there
                                         // inside the implicit solve (contact/cloth_body_contact.cpp,
                                         // contact_constraints), not only stopped after it
  double cloth_max_substep = 1.0 / 120.0; // (s) longest automatic cloth step: cloths step at
                                         // their own, coarser rate (every few substeps)
  double travel_fraction = 0.2;          // automatic substeps: per substep no body travels
                                         // more than this fraction of its thickness
  int max_substeps = 4096;               // per frame, automatic or not
  int threads = 0;                       // worker threads for the narrow phase; 0 = all cores.
                                         // Results are identical for any count.
};

struct GroundDef {
  double height = 0.0;       // plane y = height (m)
  double friction = 0.5;
  double restitution = 0.0;
};

// Creation settings of one body; the world turns them into a RigidBodyDef and a state
struct BodyDesc {
  SignedDistancePtr shape;          // in mesh coordinates; may be null when no other body
                                    // can touch this one (its samples still meet the ground)
  Points samples;                   // (s x 3) surface samples, mesh coordinates (m)
  Points mesh_vertices;             // (n x 3) the closed mesh whose level set `shape` is, mesh
  Triangles mesh_triangles;         // coordinates (m), and its (m x 3) triangles: its sharp edges and
                                    // corners are held out of cloth triangles. Empty for analytic
                                    // shapes (a box's edges come from the box itself)
  MassProperties unit_mass;         // of the shape at density 1, mesh coordinates
  double mass = 1.0;                // (kg); ignored for kinematic bodies
  Vec3 origin = Vec3::Zero();       // world position of the mesh origin (m)
  Quat orientation = Quat::Identity();  // mesh orientation in world
  Vec3 linear_velocity = Vec3::Zero();  // of the centre of mass (m/s)
  Vec3 angular_velocity = Vec3::Zero(); // world (rad/s)
  double friction = 0.5;
  double restitution = 0.0;
  bool kinematic = false;
};

struct StepStatistics {
  long long substeps = 0;          // substeps taken since the world was built
  long long cloth_steps = 0;       // cloth steps taken since the world was built
  long long cloth_solver_iterations = 0;  // conjugate-gradient iterations of the cloths' implicit steps, in all
  double cloth_solver_seconds = 0.0;      // their CPU time (preconditioner updates and CG), in all (s)
  double max_penetration = 0.0;    // deepest sample inside another body or the ground (m), last frame
  double kinetic_energy = 0.0;     // (J), now, bodies and cloths
  double elastic_energy = 0.0;     // cloths' stretch and bending energy (J), now
  double cloth_penetration = 0.0;  // deepest cloth vertex inside a body or the ground, past its
                                   // surface (m), last frame; the thickness is not counted
  double max_cloth_strain = 0.0;   // largest edge strain of any cloth, last frame
  double potential_energy = 0.0;   // gravity, -m g.x (J), now
  long long impulses = 0;          // collision and contact impulses applied, in total
  SelfCollisionStatistics self_collision;  // the cloths' self-collision work, in total
  long long cloth_gave = 0;        // cloth steps in which a cloth was stretched past what its strain
                                   // limit can hold (cloth_stages.cpp, kGiveStrain), in total
  bool finite = true;              // false once any state went NaN or infinite
};

// Wall seconds spent in each stage since the world was built
struct StageProfile {
  double broad_phase = 0.0;
  double collisions = 0.0;
  double velocities = 0.0;
  double contacts = 0.0;
  double shock_propagation = 0.0;
  double positions = 0.0;
  double sleeping = 0.0;
  double cloths = 0.0;             // all of the cloth step; of which:
  double cloth_forces = 0.0;       //   internal forces and the velocity update (the implicit solve)
  double cloth_contacts = 0.0;     //   contacts with bodies and the ground
  double cloth_strain = 0.0;       //   strain limiting
  double cloth_self_collision = 0.0;  // self-collision
  double statistics = 0.0;
};

class World {
 public:
  explicit World(const WorldSettings& settings = WorldSettings());

  void set_ground(const GroundDef& ground);
  const std::optional<GroundDef>& ground() const { return ground_; }
  // Validates and adds a body; returns its index (bodies are addressed by index)
  int add_body(const BodyDesc& desc);
  // Adds a cloth that collides with every body and the ground with this friction and keeps
  // this thickness (m) from their surfaces; returns its index
  int add_cloth(const ClothDesc& desc, double friction, double thickness, bool self_collision = true);
  int cloth_count() const { return static_cast<int>(cloths_.size()); }
  const Cloth& cloth(int i) const { return cloths_[i]; }
  Cloth& cloth(int i) { return cloths_[i]; }
  // the edges of cloth i, (j, k) with j < k, sorted
  const std::vector<std::array<int, 2>>& cloth_edges(int i) const { return cloth_contacts_[i].edges(); }
  // Makes kinematic body i follow a key track from now on (time 0 is when the world starts)
  void set_kinematic_track(int i, KinematicTrack track);
  double time() const { return time_; }  // (s) simulated so far

  // Advance one frame of length frame_dt in `substeps` equal steps, or automatic ones when
  // substeps == 0; returns the number of substeps taken. `stop`, if given, is asked before
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

  int body_count() const { return static_cast<int>(defs_.size()); }
  const RigidBodyDef& body_def(int i) const { return defs_[i]; }
  const RigidBodyState& body_state(int i) const { return states_[i]; }
  RigidBodyState& body_state(int i) { return states_[i]; }
  Pose body_mesh_pose(int i) const { return mesh_pose(defs_[i], states_[i]); }
  const WorldSettings& settings() const { return settings_; }
  const StepStatistics& statistics() const { return stats_; }
  const StageProfile& profile() const { return profile_; }
  // Deepest penetration of any sample into another body or the ground, now (m, >= 0)
  double max_penetration() const;
  bool asleep(int i) const { return asleep_[i] != 0; }
  double rest_time(int i) const { return rest_time_[i]; }  // (s) resting so far
  int sleeping_count() const;

 private:
  static constexpr int kGround = -1;
  static constexpr double kTouching = 1e-9;  // (m) closer than this to a surface is touching

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
                                    // neither levels the bodies for shock propagation nor
                                    // joins them for sleeping
  };
  struct BodyPair {
    int a, b;  // b may be kGround
    double friction, restitution;  // combined (see combine_materials in world.cpp)
  };
  // per-step scratch of shock propagation, kept so that a step allocates nothing
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
  // one substep of the rigid bodies (every stage but step_cloths)
  void step_bodies(double dt);
  // the automatic substeps and cloth steps of the next frame (see automatic_substeps)
  struct FrameSchedule {
    int substeps, cloth_steps;
  };
  FrameSchedule frame_schedule(double frame_dt) const;
  double thinnest_body() const;                                      // (m), infinite with no body
  // steps that keep each body's travel short (with `reach`: kinematic bodies only near that box)
  double body_travel_steps(double frame_dt, double thinnest, const Box3* reach = nullptr, double reach_speed = 0.0) const;
  // the speed (m/s) of body i's fastest point over the next frame: its velocities now or, for a
  // keyed body, its track's travel over the frame; gravity's gain over the frame for a dynamic body
  double body_speed(int i, double frame_dt) const;
  // the fastest moving kinematic body whose bounding sphere may meet the cloths' box within
  // the frame (m/s), 0 if none
  double kinematic_speed_near(const Box3& reach, double reach_speed, double frame_dt) const;
  // whether an awake dynamic body may touch the cloths' box `reach` within the frame
  bool dynamic_body_near(const Box3& reach, double reach_speed, double frame_dt) const;
  // stages
  void move_kinematic_bodies(double dt);
  void broad_phase(double dt);
  void update_sleeping(double dt);
  void begin_cloth_step();  // records the bodies' poses the cloths' step starts from
  void step_cloths(double dt);
  void resolve_collisions(double dt);
  void update_velocities(double dt);
  void resolve_contacts(double dt);
  void propagate_shocks();
  void update_positions(double dt);
  void gather_statistics();

  // helpers of the stages
  bool movable(int i) const { return i != kGround && !defs_[i].kinematic && !frozen_[i]; }
  bool moving_kinematic(int i) const;
  // body i's angular velocity now (rad/s, world): a kinematic body's prescribed spin, else from L
  Vec3 body_angular_velocity(int i) const {
    return defs_[i].kinematic ? spin_[i] : angular_velocity(defs_[i], states_[i]);
  }
  void compute_boxes(double dt);
  bool touching(int mover, int sleeper, double dt) const;
  // the bodies as a cloth's contacts see them (contact/cloth_body_contact.h; cloth_stages.cpp)
  class ClothContactBodies;
  double cloth_penetration() const;
  int find_island(int i);
  void wake_island(int i);
  void begin_impulse_stage(double dt, bool with_forces, bool average_velocities);
  void update_candidate(int i);
  void mark_stale(int i, ImpulseLog& log);
  void refresh_stale_candidates(ImpulseLog& log);
  Vec3 point_velocity(int i, const Vec3& x) const;
  void find_penetrations(int a, int b, double margin, long long tests, std::vector<Penetration>& out) const;
  double contact_margin(int a, int b) const;
  long long sweep_tests(int a, int b) const;
  Pose pose_at(int i, double s) const;
  bool samples_inside(int a, int b, double s, double margin, std::vector<Penetration>& out) const;
  bool box_edge_crossing(int a, int b, double s, double margin, std::vector<Penetration>& out) const;
  bool box_pair_contact(int a, int b, double s, double margin, std::vector<Penetration>& out) const;
  // body i as an oriented box at the pose, when its shape is a box
  bool body_box(int i, const Pose& pose, OrientedBox& out) const {
    if (defs_[i].box == nullptr) return false;
    out = {pose.translation, pose.rotation, defs_[i].box->half()};
    return true;
  }
  Mat3 body_impulse_matrix(int i, const Vec3& x) const;
  Mat3 pair_impulse_matrix(const Penetration& p) const;
  void exchange_impulse(const Penetration& p, const Vec3& J, ImpulseLog& log);
  bool apply_collision_impulse(const Penetration& p, double restitution, double friction, ImpulseLog& log);
  Penetration struck_point(const std::vector<Penetration>& found, const Penetration& deepest) const;
  void find_pair_penetrations(std::vector<std::vector<Penetration>>& out, bool speculative, bool reuse);
  void find_contacts();
  void refresh_contact(Penetration& p) const;
  bool apply_contact_impulse(ContactPoint& contact, ImpulseLog& log);
  void collect_impulses();
  void assign_contact_levels();
  bool check_finite() const;
  double pair_penetration(const BodyPair& pair) const;

  WorldSettings settings_;
  std::optional<GroundDef> ground_;
  std::vector<RigidBodyDef> defs_;          // (nbody) constant descriptions
  std::vector<RigidBodyState> states_;      // (nbody) state at the start of the step
  std::vector<Vec3> spin_;                  // (nbody) prescribed angular velocity of kinematic bodies (rad/s)
  std::vector<KinematicTrack> tracks_;      // (nbody) key tracks of keyed kinematic bodies (else empty)
  std::vector<RigidBodyState> candidates_;  // (nbody) candidate end-of-step states
  std::vector<Pose> candidate_poses_;       // (nbody) mesh poses of the candidates
  std::vector<Vec3> omega_;                 // (nbody) angular velocity the current impulse
                                            // stage uses at points (rad/s, world)
  std::vector<Mat3> inverse_inertia_;       // (nbody) world I^-1 at the start-of-step orientation
  std::vector<char> stale_;                 // (nbody) candidate behind the latest impulse
  std::vector<std::uint64_t> version_;      // (nbody) bumped whenever v, L or the candidate change
  std::vector<char> frozen_;                // (nbody) immovable for now (shock propagation)
  std::vector<int> level_;                  // (nbody) contact-graph distance from the ground or
                                            // a kinematic body; -1 when not connected
  std::vector<Box3> boxes_;                 // (nbody) broad-phase box over the step (m)
  std::vector<std::pair<int, int>> overlap_scratch_;  // overlapping boxes this step
  std::vector<char> asleep_;                // (nbody) sleeping: skipped by every stage
  std::vector<double> rest_time_;           // (nbody) time spent resting so far (s)
  std::vector<RigidBodyState> rest_pose_;   // (nbody) where the current rest began
  std::vector<int> island_;                 // (nbody) union-find parent; for sleepers, their island
  std::vector<Cloth> cloths_;               // (ncloth) cloths and their state
  std::vector<ClothBodyContact> cloth_contacts_;          // (ncloth) contacts with bodies and ground: friction,
                                                          // thickness (m, kept from surfaces and itself),
                                                          // inverse masses, edges, and their state and scratch
  std::vector<std::optional<SelfCollision>> cloth_self_;  // (ncloth) self-collision, when on
  std::vector<ClothObstacles> cloth_obstacles_;           // (ncloth) the bodies its self-collision keeps it from
  std::vector<Pose> cloth_step_poses_;      // (nbody) each body's mesh pose at the start of the cloths' step
  std::vector<TriangleMesh> body_meshes_;   // (nbody) the mesh of a level-set body (BodyDesc), else empty
  std::vector<ContactBody> contact_bodies_;  // (nbody) scratch: the bodies as the cloth contacts see them
  std::vector<BodyPair> pairs_;             // pairs the broad phase kept this step
  std::vector<ContactPoint> contacts_;      // contact points of this step's contact stage
  std::vector<int> body_scratch_;           // (nbody) reused by the stages
  ShockScratch shock_;                      // reused by propagate_shocks
  IslandScratch islands_;                   // this step's contact islands
  ImpulseLog log_;                          // the serial stages' impulses
  GridScratch grid_;                        // reused by overlapping_pairs
  std::vector<std::vector<Penetration>> pair_scratch_;  // (npair) samples inside, collision stage
  std::vector<char> single_test_;           // (npair) the collision stage tested the pair once
  std::vector<std::uint64_t> collision_versions_;  // (nbody) versions when the collision sweeps began
  std::vector<char> collided_;              // (nbody) took a collision impulse this step
  double dt_ = 0.0;                         // current substep (s)
  double time_ = 0.0;                       // simulated time at the start of the step (s)
  bool candidates_with_forces_ = false;     // collision stage: candidates include gravity
  bool average_velocities_ = false;         // contact stage: omega_ is the average velocity
  StepStatistics stats_;
  StageProfile profile_;
};

}  // namespace simbake
