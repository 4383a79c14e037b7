// A triangle-mesh cloth: its constant model (cloth_model.h: topology, rest state, masses, material; shared by copies)
// and its mutable state (positions and velocities), with the internal-force stages of the
// world step. Collisions with bodies and the ground are contact/cloth_body_contact.h's (the
// world calls them, world/cloth_stages.cpp); this class only knows the cloth itself.
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

#include "cloth/cloth_model.h"
#include "math/types.h"

#include <Eigen/SparseCore>

#include <memory>
#include <vector>

namespace simbake {

namespace cloth_detail {
class Preconditioner; // cloth/multigrid.h: z = P^-1 r for the implicit system's conjugate gradients
}

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
  // the same with the vertices marked in `held` (n) held still as if pinned, for this call;
  // returns the impulses (n x 3, N s) the held vertices would have taken (their edges' pushes
  // against them, which the held ones absorb: what momentum the call did not keep)
  Points limit_strain_holding(double dt, const std::vector<char>& held);
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
  const Triangles& triangles() const { return model_->triangles; }
  const Eigen::VectorXd& masses() const { return model_->mass; }      // (n) lumped masses (kg)
  const std::vector<char>& pinned() const { return model_->pinned; }  // (n) 1 if pinned
  const Eigen::VectorXd& inverse_masses() const { return model_->inverse_mass; }  // (n) 1 / mass, 0 if pinned
  Points& positions() { return x_; }                            // (n x 3) (m)
  const Points& positions() const { return x_; }
  Points& velocities() { return v_; }                           // (n x 3) (m/s)
  const Points& velocities() const { return v_; }
  const ClothMaterial& material() const { return model_->material; }
  ClothIntegrator integrator() const { return model_->integrator; }
  long long solver_iterations() const { return solver_iterations_; }  // implicit solves' CG iterations so far
  double solver_seconds() const { return solver_seconds_; }  // their CPU time (s): preconditioner update and CG
  bool uses_multigrid() const;  // the implicit solve's preconditioner is multigrid (else block-Jacobi)

 private:
  // the constant half, shared by copies (cloth_model.h)
  std::shared_ptr<const ClothModel> model_;
  // the state
  Points x_, v_;
  // the implicit step's scratch: its matrix (the model's pattern), rebuilt each step, and
  // z = P^-1 r for its solve, whose structure is built once and whose values change every
  // step, so a copy of a Cloth takes its own (clone) before its first solve
  Eigen::SparseMatrix<double> system_;
  std::shared_ptr<cloth_detail::Preconditioner> preconditioner_;
  long long solver_iterations_ = 0;
  double solver_seconds_ = 0.0;

  void explicit_velocities(double dt, const Vec3& gravity, std::vector<ClothContactConstraint>* constraints);
  void implicit_velocities(double dt, const Vec3& gravity, std::vector<ClothContactConstraint>* constraints);
  // the strain limiter, with the vertices marked in `held` (n, or null) held still besides
  // the pinned ones; a held or pinned vertex's inverse mass is 0. With `reaction` (n x 3),
  // the impulses each edge would have given its held (not pinned) end are summed there
  void limit_strain(double dt, bool global, const std::vector<char>* held, Points* reaction);
  double inverse_mass(int k, const std::vector<char>* held) const {
    return held && (*held)[k] ? 0.0 : model_->inverse_mass[k];
  }
  double strain_sweep(double dt, const std::vector<int>& order, const std::vector<char>* held, Points* reaction);
  void project_strain(double dt, const std::vector<char>* held, Points* reaction);
  // the sum of the squared distances by which the edges are past their bounds at candidate
  // positions p (project_strain's line search)
  double bound_violation(const Points& p, const std::vector<char>* held) const;
};

}  // namespace simbake
