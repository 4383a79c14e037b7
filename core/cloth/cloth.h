// A triangle-mesh cloth: its constant model (cloth_model.h: topology, rest state, masses,
// material; shared by copies), its state (cloth_data.h: positions and velocities) and its
// implicit solver's scratch (integrators.h), with the cloth's own stages as methods over them.
// Collisions with bodies and the ground are contact/cloth_body_contact.h's, with itself
// self_collision.h's; the step that calls them all in order is cloth_step.h's.
//
// The cloth's own stages, in the order a step calls them:
//   update_velocities(dt, gravity)   forces (stretch/shear or membrane, bending, damping) and
//                                    the velocity update: explicit or implicit (backward Euler),
//                                    with the contacts the caller passes held inside it
//                                    (integrators.h)
//   ... collision impulses change v ...
//   limit_strain(dt)                 impulses along over-stretched (and, per the compression
//                                    mode, over-compressed) edges so that x + dt v respects them
//                                    (strain_limiting.h)
//   update_positions(dt)             x += dt v; pinned vertices stay where they are
#pragma once

#include "cloth/cloth_data.h"
#include "cloth/cloth_model.h"
#include "cloth/integrators.h"
#include "cloth/strain_limiting.h"
#include "math/types.h"

#include <memory>
#include <vector>

namespace simbake {

class Cloth {
 public:
  explicit Cloth(const ClothDesc& desc);  // validates and builds edges, hinges, masses

  // stages (see the top of this file)
  // constraints: at most one per free vertex (pinned ones are skipped), or null
  void update_velocities(double dt, const Vec3& gravity, std::vector<ClothContactConstraint>* constraints = nullptr) {
    simbake::update_velocities(*model_, data_, solver_, dt, gravity, constraints);
  }
  void limit_strain(double dt, bool global = true) { simbake::limit_strain(*model_, data_, dt, global); }
  // the same with the vertices marked in `held` (n) held still as if pinned, for this call;
  // returns the impulses (n x 3, N s) the held vertices would have taken
  Points limit_strain_holding(double dt, const std::vector<char>& held) {
    return simbake::limit_strain_holding(*model_, data_, dt, held);
  }
  void update_positions(double dt) { simbake::update_positions(*model_, data_, dt); }

  // the largest stable explicit substep (speed-of-sound limit) for the current material (s)
  double stable_explicit_step() const { return model_->stable_step; }
  // elastic energy (stretch + bending), kinetic energy, and gravity potential -m g.x (J)
  double elastic_energy() const;
  double kinetic_energy() const;
  double potential_energy(const Vec3& gravity) const;
  // largest edge strain |l| / L - 1 now, and at the candidate positions x + dt v
  double max_strain() const;
  double candidate_strain(double dt) const { return simbake::candidate_strain(*model_, data_, dt); }
  // area-weighted vertex normals of the current shape (n x 3)
  Points vertex_normals() const;

  const ClothModel& model() const { return *model_; }
  const ClothData& data() const { return data_; }
  int vertex_count() const { return static_cast<int>(data_.x.rows()); }
  const Triangles& triangles() const { return model_->triangles; }
  const Eigen::VectorXd& masses() const { return model_->mass; }      // (n) lumped masses (kg)
  const std::vector<char>& pinned() const { return model_->pinned; }  // (n) 1 if pinned
  const Eigen::VectorXd& inverse_masses() const { return model_->inverse_mass; }  // (n) 1 / mass, 0 if pinned
  Points& positions() { return data_.x; }                       // (n x 3) (m)
  const Points& positions() const { return data_.x; }
  Points& velocities() { return data_.v; }                      // (n x 3) (m/s)
  const Points& velocities() const { return data_.v; }
  const ClothMaterial& material() const { return model_->material; }
  ClothIntegrator integrator() const { return model_->integrator; }
  long long solver_iterations() const { return solver_.iterations; }  // implicit solves' CG iterations so far
  double solver_seconds() const { return solver_.seconds; }  // their CPU time (s): preconditioner update and CG
  bool uses_multigrid() const { return simbake::uses_multigrid(solver_); }

 private:
  std::shared_ptr<const ClothModel> model_;  // the constant half, shared by copies
  ClothData data_;                           // the state
  ClothSolver solver_;                       // the implicit step's scratch
};

}  // namespace simbake
