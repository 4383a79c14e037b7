// The constant half of a cloth (a model / data split, as MuJoCo's): what a cloth is made of
// (ClothDesc, ClothMaterial: the only home of their defaults, which the Python bindings read)
// and what is built from it once (ClothModel: topology, rest state, masses, pins, material,
// the element forces, the implicit system's pattern, the explicit stability limit). Copies of
// a Cloth share one model and hold only their state (cloth_data.h) and the solver's scratch
// (integrators.h).
#pragma once

#include "math/types.h"

#include <memory>
#include <vector>

namespace simbake {

namespace cloth_detail {
class ForceModel;     // cloth/cloth_forces.h: topology, rest state and element forces
class MatrixPattern;  // cloth/cloth_forces.h: the implicit system's sparsity pattern
}

enum class InPlaneModel { kSprings, kMembrane };      // springs along edges | StVK membrane per triangle
enum class CompressionMode { kSubgrid, kEnforce, kNone };
enum class ClothIntegrator { kExplicit, kImplicit };
// the implicit solve's preconditioner: automatic = multigrid from 1,000 free vertices when none is
// pinned, else block-Jacobi (integrators.cpp says why)
enum class ClothPreconditioner { kAutomatic, kBlockJacobi, kMultigrid };

struct ClothMaterial {
  InPlaneModel model = InPlaneModel::kSprings;
  double stretch_stiffness = 1000.0;  // the sheet's stiffness Y (N/m): the membrane's Young's modulus x
                                      // thickness; springs get E = Y x (area share) / L each (cloth_forces.cpp)
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
  // vertices attached to something that moves them (a body's surface: contact/cloth_attachment.h):
  // like pinned ones they are outside the cloth's solve, of infinite mass, but their velocity
  // is what the caller sets before each step, and they move with it
  std::vector<int> attached;
  ClothIntegrator integrator = ClothIntegrator::kImplicit;
  double tolerance = 1e-3;            // implicit: the linear solve's relative residual (mass norm)
  ClothPreconditioner preconditioner = ClothPreconditioner::kAutomatic;  // implicit: of its conjugate gradients
  double friction = 0.3;              // Coulomb coefficient against bodies and the ground
  double thickness = 0.005;           // (m) kept from bodies, the ground and the cloth's own other layers
  bool self_collision = true;         // kept from passing through itself (at `thickness`)
};

// Built once from a ClothDesc (cloth_model.cpp validates it and says how), never changed after
struct ClothModel {
  explicit ClothModel(const ClothDesc& desc);

  // the description's, checked
  ClothMaterial material;
  ClothIntegrator integrator;
  double tolerance;
  double friction;
  double thickness;              // (m)
  bool self_collision;
  // built from it
  Points rest;                   // (n x 3) rest positions (m)
  Triangles triangles;           // (m x 3)
  Eigen::VectorXd mass;          // (n) lumped masses (kg)
  // (n) 1 if the cloth's stages never change its velocity: pinned (held still) or attached
  // (moving as the caller sets its velocity): of infinite mass to every stage, and outside the
  // implicit system, whose forces see it at x + dt v
  std::vector<char> pinned;
  std::vector<char> attached;    // (n) 1 if attached (then pinned is 1 too)
  Eigen::VectorXd inverse_mass;  // (n) 1 / mass, 0 where pinned (the strain limiter's weights)
  std::vector<int> free_index;   // vertex -> its block in the implicit system, -1 if pinned
  int free_count = 0;
  // edges, hinges, membrane rest frames and the element forces
  std::shared_ptr<const cloth_detail::ForceModel> forces;
  std::shared_ptr<const cloth_detail::MatrixPattern> pattern;
  double stable_step = 0.0;      // the largest stable explicit substep (s)
  double max_correction = 0.0;   // the strain limiter's largest length correction per step (m)
  std::vector<int> forward_order, backward_order;  // the strain limiter's sweep orders
};

}  // namespace simbake
