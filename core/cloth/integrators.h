// A cloth's velocity update (forces and gravity; explicit or implicit, with the contacts the
// caller passes held inside it) and position update (the method is at the top of
// integrators.cpp), and the implicit solve's scratch.
#pragma once

#include "cloth/cloth_data.h"
#include "cloth/cloth_model.h"

#include <Eigen/SparseCore>

#include <memory>
#include <vector>

namespace simbake {

namespace cloth_detail {
class Preconditioner;  // cloth/multigrid.h: z = P^-1 r for the implicit system's conjugate gradients
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

// The implicit solve's scratch, one per cloth: its matrix (the model's pattern), rebuilt each
// step, and z = P^-1 r for its conjugate gradients, whose structure is built once and whose
// values change every step (a copy of a cloth takes its own, clone, before its first solve);
// and the work it has done
struct ClothSolver {
  Eigen::SparseMatrix<double> system;
  std::shared_ptr<cloth_detail::Preconditioner> preconditioner;
  long long iterations = 0;  // conjugate-gradient iterations so far
  double seconds = 0.0;      // their CPU time (s): preconditioner updates and CG
};

// A cloth's solver, its preconditioner as `choice` asks (automatic: integrators.cpp says how)
ClothSolver make_solver(const ClothModel& model, ClothPreconditioner choice);
// whether the solver's preconditioner is multigrid (else block-Jacobi)
bool uses_multigrid(const ClothSolver& solver);

// Forces (stretch/shear or membrane, bending, damping), gravity and the velocity update over
// dt (s): explicit or implicit (backward Euler), with the contacts `constraints` (at most one
// per free vertex; pinned ones are skipped) held inside it, or null. Pinned vertices never move;
// attached ones (ClothDesc::attached) keep the velocity they came with, which the forces on the
// rest of the cloth see (at x + dt v), as the solve sees a pinned vertex at rest
void update_velocities(const ClothModel& model, ClothData& data, ClothSolver& solver, double dt, const Vec3& gravity,
                       std::vector<ClothContactConstraint>* constraints);

// x += dt v; pinned vertices stay where they are, attached ones move with their velocity
void update_positions(const ClothModel& model, ClothData& data, double dt);

}  // namespace simbake
