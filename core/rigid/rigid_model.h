// The constant half of the rigid bodies (a model / data split, as MuJoCo's mjModel and mjData):
// what each body is (its RigidBodyDef: mass properties, shape, surface samples), its mesh, its
// key track, and the ground. Built body by body (add_body) before the world steps, never
// changed by a step. The state is rigid_data.h's; the per-step scratch rigid_scratch.h's.
#pragma once

#include "geometry/mass_properties.h"
#include "geometry/mesh.h"
#include "rigid/joint_model.h"
#include "rigid/kinematic_track.h"
#include "rigid/rigid_body.h"

#include <cstdint>
#include <optional>
#include <utility>
#include <vector>

namespace simbake {

// A pair's or a contact's other body when it is the ground
inline constexpr int kGround = -1;

struct GroundDef {
  double height = 0.0;       // plane y = height (m)
  double friction = 0.5;     // Coulomb coefficient
  double restitution = 0.0;  // in [0, 1]
};

// Creation settings of one body; add_body turns them into a RigidBodyDef and a state
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
  double friction = 0.5;            // Coulomb coefficient
  double restitution = 0.0;         // in [0, 1]
  bool kinematic = false;           // infinite mass, moved only by its own motion (or keys)
};

struct RigidModel {
  std::vector<RigidBodyDef> defs;       // (nbody) constant descriptions
  std::vector<TriangleMesh> meshes;     // (nbody) the mesh of a level-set body (BodyDesc), else empty
  std::vector<KinematicTrack> tracks;   // (nbody) key tracks of keyed kinematic bodies (else empty)
  std::optional<GroundDef> ground;      // the plane y = height, if any
  // joints and collision filtering (rigid/joint_model.h, rigid/collision_filter.h)
  std::vector<JointDef> joints;                    // (njoint) constant definitions
  std::vector<std::vector<int>> body_joints;       // (nbody) the joints of each body
  std::vector<std::pair<int, int>> filtered_pairs; // pairs (a < b) that never collide, sorted
  std::vector<std::uint64_t> groups;               // (nbody) its collision groups (bit g: group g)
  std::vector<std::uint64_t> group_filters;        // (ngroup) the groups group g does not collide with

  int body_count() const { return static_cast<int>(defs.size()); }
  // whether any pair may be kept from colliding (joints, filtered pairs, groups)
  bool filters_collisions() const { return !joints.empty() || !filtered_pairs.empty() || !group_filters.empty(); }
};

// Throws std::invalid_argument naming what is wrong with the ground, or with a body's description
void check_ground(const GroundDef& ground);
void check_body(const BodyDesc& desc);

// The constant description of a checked body: principal axes and moments, bounding radius,
// thickness, sample blocks
RigidBodyDef make_body_def(const BodyDesc& desc);

// The constant definition of a checked joint between bodies of the model (rigid/joint_model.h)
JointDef make_joint_def(const RigidModel& model, const JointDesc& desc);

}  // namespace simbake
