// A triangle-mesh cloth: its constant description (topology, rest state, masses, material)
// and its mutable state (positions and velocities), with the internal-force stages of the
// world step. Collisions with bodies and the ground are the world's job (world/cloth_stages);
// this class only knows the cloth itself.
//
// Stages the world calls, in order, each substep (DESIGN.md, "The world step", stage 6):
//   update_velocities(dt, gravity)   forces (stretch/shear or membrane, bending, damping) and
//                                    the velocity update: explicit or implicit (backward Euler),
//                                    with the contacts the world passes held inside it
//   ... the world's collision impulses change v ...
//   limit_strain(dt)                 impulses along over-stretched (and, per the compression
//                                    mode, over-compressed) edges so that x + dt v respects them
//   update_positions(dt)             x += dt v; pinned vertices stay where they are
#pragma once

#include "math/types.h"

#include <Eigen/SparseCore>

#include <memory>
#include <vector>

namespace simbake {

namespace cloth_detail {
class ForceModel;     // cloth/cloth_forces.h: topology, rest state and element forces
class MatrixPattern;  // cloth/cloth_forces.h: the implicit system's sparsity pattern
class Preconditioner; // cloth/multigrid.h: z = P^-1 r for the implicit system's conjugate gradients
}

enum class InPlaneModel { kSprings, kMembrane };      // springs along edges | StVK membrane per triangle
enum class CompressionMode { kSubgrid, kEnforce, kNone };
enum class ClothIntegrator { kExplicit, kImplicit };
// the implicit solve's preconditioner: automatic = multigrid from 1,000 free vertices when none is
// pinned, else block-Jacobi (cloth.cpp says why)
enum class ClothPreconditioner { kAutomatic, kBlockJacobi, kMultigrid };

struct ClothMaterial {
  InPlaneModel model = InPlaneModel::kSprings;
  double stretch_stiffness = 1000.0;  // the sheet's stiffness Y (N/m): the membrane's Young's modulus x
                                      // thickness; springs get E = Y x (area share) / L each (cloth.cpp)
  double poisson_ratio = 0.3;         // membrane only
  double bend_stiffness = 1e-4;       // B (N m): bending energy density 1/2 B (1/R1 + 1/R2)^2
  double damping = 0.01;              // Rayleigh stiffness-proportional damping coefficient (s)
  double strain_limit = 0.1;          // largest stretch (|l| / L - 1) allowed; 0 disables
  CompressionMode compression = CompressionMode::kSubgrid;
  double subgrid_scale = 0.01;        // subgrid: stiffness multiplier under compression
};

struct ClothDesc {
  Points rest;                        // (n x 3) rest positions = initial positions (m)
  Triangles triangles;                // (m x 3)
  double area_density = 0.1;          // (kg/m^2), lumped to vertices (a third of each triangle)
  ClothMaterial material;
  std::vector<int> pinned;            // vertices held fixed
  ClothIntegrator integrator = ClothIntegrator::kImplicit;
  double tolerance = 1e-3;            // implicit: the linear solve's relative residual (mass norm)
  ClothPreconditioner preconditioner = ClothPreconditioner::kAutomatic;  // implicit: of its conjugate gradients
};

// A contact held inside the velocity update (Baraff and Witkin 1998, "Large steps in cloth
// simulation", section 5.3: constraint filtering): after the update, the vertex's velocity
// along the unit `normal` is `speed` (the surface's own speed along it, or what lands the
// vertex on it), and, when `stick` (static friction), its velocity across the normal is the
// surface's (`surface_velocity`'s); the rest of the cloth answers to that within the same
// implicit solve, instead of being stopped vertex by vertex after it. The update sets
// `impulse`: what the surface gave the vertex along the normal (N s; negative means it had to
// pull, and the caller should let the vertex go), and `friction`: across it (N s; zero unless
// `stick`: the caller checks it against the friction cone).
struct ClothContactConstraint {
  int vertex = -1;
  Vec3 normal = Vec3::UnitY();
  double speed = 0.0;                     // (m/s)
  bool stick = false;
  Vec3 surface_velocity = Vec3::Zero();   // (m/s) used when stick
  double impulse = 0.0;                   // (N s) set by update_velocities
  Vec3 friction = Vec3::Zero();           // (N s) set by update_velocities
};

class Cloth {
 public:
  explicit Cloth(const ClothDesc& desc);  // validates and builds edges, hinges, masses

  // stages (see the top of this file)
  // constraints: at most one per free vertex (pinned ones are skipped), or null
  void update_velocities(double dt, const Vec3& gravity, std::vector<ClothContactConstraint>* constraints = nullptr);
  void limit_strain(double dt, bool global = true);
  // the same with the vertices marked in `held` (n) held still as if pinned, for this call
  void limit_strain_holding(double dt, const std::vector<char>& held);
  void update_positions(double dt);

  // the largest stable explicit substep (speed-of-sound limit) for the current material (s)
  double stable_explicit_step() const;
  // elastic energy (stretch + bending), kinetic energy, and gravity potential -m g.x (J)
  double elastic_energy() const;
  double kinetic_energy() const;
  double potential_energy(const Vec3& gravity) const;
  // largest edge strain |l| / L - 1 now, and at the candidate positions x + dt v
  double max_strain() const;
  double candidate_strain(double dt) const;
  // area-weighted vertex normals of the current shape (n x 3)
  Points vertex_normals() const;

  int vertex_count() const { return static_cast<int>(x_.rows()); }
  const Triangles& triangles() const { return triangles_; }
  const Eigen::VectorXd& masses() const { return mass_; }      // (n) lumped masses (kg)
  const std::vector<char>& pinned() const { return pinned_; }  // (n) 1 if pinned
  Points& positions() { return x_; }                            // (n x 3) (m)
  const Points& positions() const { return x_; }
  Points& velocities() { return v_; }                           // (n x 3) (m/s)
  const Points& velocities() const { return v_; }
  const ClothMaterial& material() const { return material_; }
  ClothIntegrator integrator() const { return integrator_; }
  long long solver_iterations() const { return solver_iterations_; }  // implicit solves' CG iterations so far
  double solver_seconds() const { return solver_seconds_; }  // their CPU time (s): preconditioner update and CG
  bool uses_multigrid() const;  // the implicit solve's preconditioner is multigrid (else block-Jacobi)

 private:
  // (the helper implementing this class adds the private members it needs:
  //  edges and rest lengths, hinges and rest angles, triangle rest frames, solver scratch)
  ClothMaterial material_;
  ClothIntegrator integrator_;
  double tolerance_;
  long long solver_iterations_ = 0;
  double solver_seconds_ = 0.0;
  Triangles triangles_;
  Eigen::VectorXd mass_;
  std::vector<char> pinned_;
  Points x_, v_;

  // edges, hinges, membrane rest frames and the element forces; constant after
  // construction, so copies of a Cloth share it
  std::shared_ptr<const cloth_detail::ForceModel> model_;
  std::shared_ptr<const cloth_detail::MatrixPattern> pattern_;
  Eigen::SparseMatrix<double> system_;  // the implicit step's matrix (pattern_'s), rebuilt each step
  std::vector<int> free_index_;  // vertex -> its block in the implicit system, -1 if pinned
  // z = P^-1 r for the implicit solve, built once; its values change every step, so a copy
  // of a Cloth takes its own (clone) before its first solve
  std::shared_ptr<cloth_detail::Preconditioner> preconditioner_;
  int free_count_ = 0;
  double stable_step_ = 0.0;     // stable_explicit_step(), computed once
  double max_correction_ = 0.0;  // the strain limiter's largest length correction per step (m)
  std::vector<int> forward_order_, backward_order_;  // the strain limiter's sweep orders

  void explicit_velocities(double dt, const Vec3& gravity, std::vector<ClothContactConstraint>* constraints);
  void implicit_velocities(double dt, const Vec3& gravity, std::vector<ClothContactConstraint>* constraints);
  double compute_stable_step() const;
  double largest_omega2(bool stretch, bool bend) const;
  double strain_sweep(double dt, const std::vector<int>& order);
  void project_strain(double dt);
};

}  // namespace simbake
