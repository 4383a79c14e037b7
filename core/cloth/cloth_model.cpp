// A cloth's model built from its description: the description checked, lumped masses, pins,
// the element forces and the implicit system's pattern, the strain limiter's sweep orders
// and the explicit integrator's stability limit.
//
// Stable explicit step (speed of sound): a chain of springs k = E / L and vertex masses
// m = rho_line L has its fastest mode at omega^2 = 4 k / m = 4 E / (rho_line L^2), and
// symplectic Euler needs dt omega <= 2, i.e. dt <= L / sqrt(E / rho_line): the time for a
// sound wave to cross one edge. For any mesh, material and bending together, omega_max^2 is
// the largest eigenvalue of M^-1/2 H M^-1/2 at rest, bounded above by its largest
// Gershgorin row sum (exact for the chain, ~1.2x for a grid). With stiffness-proportional
// damping the mode obeys x'' = -omega^2 (x + damping x'), and symplectic Euler with explicit
// damping is stable (Jury's test on z^2 - (2 - a - b) z + 1 - b, a = dt^2 omega^2,
// b = damping dt omega^2) when a + 2 b <= 4, i.e. dt <= sqrt(damping^2 + 4 / omega^2) -
// damping (about 2 / (damping omega^2) once damping omega >> 1: strong damping makes explicit
// steps tiny). The bound includes the stiffening that stretch up to the strain limit brings
// (springs: the transverse term, 1 + e / (1 + e); membrane: the StVK tangent, (3 (1 + e)^2
// - 1) / 2; e = 10% when unlimited) and a safety factor of 0.75 (a stretched membrane near
// the bound can still go unstable over seconds through nonlinear coupling).
#include "cloth/cloth_model.h"

#include "cloth/cloth_forces.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace simbake {

namespace {

constexpr double kStableSafety = 0.75;      // of the explicit stability bound
// The most an edge's length is corrected in one step, x the cloth's mean edge length. Far
// more than any step of a free cloth needs; it bounds the velocity the limiter can give
// where it fights a collision (cloth pushed by a keyed body against its own pins), which
// would otherwise grow without bound
constexpr double kMaxCorrection = 0.1;

void require(bool ok, const std::string& message) {
  if (!ok) throw std::invalid_argument("cloth: " + message);
}

Vec3 row(const Points& x, int k) { return x.row(k).transpose(); }

// An upper bound of the largest eigenvalue of M^-1/2 H M^-1/2 over the free vertices at
// rest (the squared fastest frequency), for in-plane and/or bending terms: its largest
// Gershgorin row sum
double largest_omega2(const ClothModel& m, bool stretch, bool bend) {
  if (m.free_count == 0) return 0.0;
  Eigen::SparseMatrix<double> H = m.pattern->make_matrix();
  cloth_detail::Assembly what;
  what.stretch = stretch;
  what.bend = bend;
  what.hessian_weight = 1.0;
  what.pattern = m.pattern.get();
  what.matrix = &H;
  m.forces->assemble(m.rest, what);  // at rest the Hessian equals its material part
  Eigen::VectorXd inverse_sqrt_mass(3 * m.free_count);
  for (int k = 0; k < static_cast<int>(m.rest.rows()); ++k) {
    if (m.free_index[k] >= 0) inverse_sqrt_mass.segment<3>(3 * m.free_index[k]).setConstant(1.0 / std::sqrt(m.mass[k]));
  }
  double omega2 = 0.0;
  for (int col = 0; col < H.outerSize(); ++col) {  // symmetric: column sums are row sums
    double sum = 0.0;
    for (Eigen::SparseMatrix<double>::InnerIterator it(H, col); it; ++it) {
      sum += std::abs(it.value()) * inverse_sqrt_mass[it.row()];
    }
    omega2 = std::max(omega2, sum * inverse_sqrt_mass[col]);
  }
  return omega2;
}

// the explicit stability limit (derivation at the top of this file)
double explicit_stable_step(const ClothModel& m) {
  if (m.free_count == 0) return std::numeric_limits<double>::infinity();
  // stiffening under stretch up to the strain limit (nominal 10% when unlimited)
  const double e = m.material.strain_limit > 0.0 ? m.material.strain_limit : 0.1;
  const double stiffening =
      m.material.model == InPlaneModel::kMembrane ? 0.5 * (3.0 * (1.0 + e) * (1.0 + e) - 1.0) : 1.0 + e / (1.0 + e);
  const double omega2 = stiffening * largest_omega2(m, true, false) + largest_omega2(m, false, true);
  if (!(omega2 > 0.0)) return std::numeric_limits<double>::infinity();
  const double c = m.material.damping;
  return kStableSafety * (std::sqrt(c * c + 4.0 / omega2) - c);
}

}  // namespace

ClothModel::ClothModel(const ClothDesc& desc)
    : material(desc.material),
      integrator(desc.integrator),
      tolerance(desc.tolerance),
      friction(desc.friction),
      thickness(desc.thickness),
      self_collision(desc.self_collision),
      rest(desc.rest),
      triangles(desc.triangles) {
  // validate the description
  const int n = static_cast<int>(desc.rest.rows());
  require(n >= 3, "needs at least 3 vertices");
  require(desc.rest.allFinite(), "rest positions must be finite");
  require(desc.triangles.rows() >= 1, "needs at least one triangle");
  require(desc.area_density > 0.0 && std::isfinite(desc.area_density), "area_density must be > 0");
  const ClothMaterial& m = desc.material;
  require(m.stretch_stiffness >= 0.0 && std::isfinite(m.stretch_stiffness), "stretch_stiffness must be >= 0");
  require(m.poisson_ratio >= 0.0 && m.poisson_ratio <= 0.5, "poisson_ratio must be in [0, 0.5]");
  require(m.bend_stiffness >= 0.0 && std::isfinite(m.bend_stiffness), "bend_stiffness must be >= 0");
  require(m.damping >= 0.0 && std::isfinite(m.damping), "damping must be >= 0");
  require(m.strain_limit >= 0.0 && std::isfinite(m.strain_limit), "strain_limit must be >= 0");
  require(m.subgrid_scale >= 0.0 && m.subgrid_scale <= 1.0, "subgrid_scale must be in [0, 1]");
  require(desc.tolerance > 0.0 && desc.tolerance < 1.0, "tolerance must be in (0, 1)");
  require(desc.friction >= 0.0 && std::isfinite(desc.friction), "friction must be >= 0");
  require(desc.thickness >= 0.0 && std::isfinite(desc.thickness), "thickness must be >= 0");

  // lumped masses: a third of each triangle's rest area times the area density
  mass = Eigen::VectorXd::Zero(n);
  for (int t = 0; t < desc.triangles.rows(); ++t) {
    const int a = desc.triangles(t, 0), b = desc.triangles(t, 1), c = desc.triangles(t, 2);
    for (int v : {a, b, c}) {
      require(v >= 0 && v < n, "triangle " + std::to_string(t) + " uses vertex " + std::to_string(v) +
                                   " that does not exist (the cloth has " + std::to_string(n) + ")");
    }
    require(a != b && b != c && a != c, "triangle " + std::to_string(t) + " repeats a vertex");
    const double area = 0.5 * (row(rest, b) - row(rest, a)).cross(row(rest, c) - row(rest, a)).norm();
    require(area > 0.0, "triangle " + std::to_string(t) + " has zero area");
    for (int v : {a, b, c}) mass[v] += desc.area_density * area / 3.0;
  }
  for (int v = 0; v < n; ++v) require(mass[v] > 0.0, "vertex " + std::to_string(v) + " belongs to no triangle");

  // pinned vertices and the implicit system's numbering of the free ones
  pinned.assign(n, 0);
  for (int p : desc.pinned) {
    require(p >= 0 && p < n, "pinned vertex " + std::to_string(p) + " does not exist (the cloth has " +
                                 std::to_string(n) + ")");
    pinned[p] = 1;
  }
  attached.assign(n, 0);
  for (int p : desc.attached) {
    require(p >= 0 && p < n, "attached vertex " + std::to_string(p) + " does not exist (the cloth has " +
                                 std::to_string(n) + ")");
    require(!pinned[p] || attached[p], "vertex " + std::to_string(p) + " is both pinned and attached");
    require(!attached[p], "attached vertex " + std::to_string(p) + " is listed twice");
    pinned[p] = attached[p] = 1;
  }
  free_index.assign(n, -1);
  inverse_mass = Eigen::VectorXd::Zero(n);
  for (int v = 0; v < n; ++v) {
    if (!pinned[v]) free_index[v] = free_count++;
    if (!pinned[v]) inverse_mass[v] = 1.0 / mass[v];
  }

  forces = std::make_shared<const cloth_detail::ForceModel>(desc.rest, desc.triangles, desc.material);
  pattern = std::make_shared<const cloth_detail::MatrixPattern>(*forces, free_index);
  // the strain limiter's edge orders: as stored (sorted by vertex indices), and reversed
  forward_order.resize(forces->edges().size());
  for (size_t q = 0; q < forward_order.size(); ++q) forward_order[q] = static_cast<int>(q);
  backward_order.assign(forward_order.rbegin(), forward_order.rend());
  stable_step = explicit_stable_step(*this);
  double total_length = 0.0;
  for (const cloth_detail::Edge& e : forces->edges()) total_length += e.rest;
  max_correction = kMaxCorrection * total_length / static_cast<double>(forces->edges().size());
}

}  // namespace simbake
