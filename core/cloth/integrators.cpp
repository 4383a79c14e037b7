// The velocity update of a cloth step, from its internal forces (cloth_forces.h) and gravity,
// and the position update.
//
// Implicit step (Baraff and Witkin 1998, "Large steps in cloth simulation"): one linearized
// backward-Euler step,
//        (M - dt^2 K - dt D) dv = dt (f + D v + M g),     x_new = x + dt (v + dv),
// with K = df/dx = -H the stiffness and D = df/dv = -damping x H_m. Baraff and Witkin
// linearize the elastic force about x: f(x) + dt K(x) (v + dv). Here it is linearized about
// the inertial prediction y = x + dt v instead, f(y) + dt K(y) dv: the same to first order
// (and identical for linear forces), and exactly the first Newton iteration of backward
// Euler's incremental potential started at y. The difference matters for rotation: with
// the linearization at x, a cloth spinning at omega loses angular momentum at a rate that
// grows with (omega_spring dt)^2, because x + dt v stretches every edge by (omega dt)^2 / 2,
// which the next step's stiff forces see in full (a stiff cloth spinning at a few rad/s loses
// nearly all its kinetic energy within a second); about y it keeps backward Euler's own
// exp(-2 omega^2 dt t) whatever the stiffness. H is made positive
// semi-definite element by element (springs: the transverse term dropped under compression;
// membrane: the 9x9 Hessian projected by eigen-decomposition; bending: its Gauss-Newton part
// only), so M + dt^2 H + damping dt H_m is symmetric positive definite. It is assembled
// straight into an Eigen sparse matrix of fixed pattern (MatrixPattern, built once) over the
// unpinned vertices only (pinned rows and columns removed: their velocity is zero and stays
// so; an attached vertex's is what its attachment prescribed, and stays so: the elastic and
// damping forces on its neighbours see it at x + dt v), elastic and damping terms in one
// pass over the elements, scaled by M^-1/2 on both sides, and solved by preconditioned conjugate gradients (our own loop, multiplying the
// preconditioner's 3x3-block copy of the matrix: 1.4x fewer bytes than Eigen's scalar one)
// to a relative residual `tolerance`, started from zero. The preconditioner (cloth/multigrid.h)
// is a smoothed-aggregation multigrid V-cycle, whose iteration count stays nearly flat as
// the mesh is refined, for cloths of 1,000 free vertices or more; small cloths keep
// block-Jacobi (its iterations grow as 1/h; see kMultigridVertices). (A sparse Cholesky
// factorization each step costs many times the conjugate gradients at these sizes.)
// For a cloth with no pinned vertex, the net momentum error the solver leaves is removed
// (the exact solution changes the total momentum by dt M g only). Gravity is an external
// force m g on unpinned vertices.
// Explicit step: symplectic Euler, v += dt M^-1 f (positions then move with the new v).
#include "cloth/integrators.h"

#include "cloth/cloth_forces.h"
#include "cloth/multigrid.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include <time.h>

namespace simbake {

namespace {

// the conjugate gradients multiply by the lower triangle in single precision (lower_kernels.h)
// when the solve's relative residual is this or looser: its rounding (1e-7 of each product)
// would show in a tighter solve
constexpr double kSinglePrecisionTolerance = 1e-5;
constexpr int kMaxSolverIterations = 2000;  // conjugate gradient iterations per implicit step (at most)
constexpr int kMultigridVertices = 1000;    // automatic: multigrid from this many free vertices
// Automatic preconditioner: multigrid for a cloth of kMultigridVertices free vertices or more,
// block-Jacobi otherwise. Multigrid's iteration count stays nearly flat as the mesh is
// refined, block-Jacobi's grows as 1/h; below about a thousand vertices block-Jacobi's cheaper
// iterations win. Pinned cloths take multigrid too: a body's contact by the pins cannot hand
// its push to a free vertex of round-off weight (contact/cloth_body_contact.cpp, kMaxLever).

void require(bool ok, const std::string& message) {
  if (!ok) throw std::invalid_argument("cloth: " + message);
}

Vec3 row(const Points& x, int k) { return x.row(k).transpose(); }

// CPU time of the calling thread (s), which the solver statistics count: unlike wall time,
// it is not inflated by other processes on a shared machine
double thread_cpu_seconds() {
  timespec t;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

// start + (A x) at block row i, A in 3x3 blocks (summed onto `start`, in block order)
Vec3 block_row_product(const cloth_detail::BlockMatrix& a, const Eigen::VectorXd& x, int i, Vec3 start = Vec3::Zero()) {
  Vec3 q = start;
  for (int k = a.start[i]; k < a.start[i + 1]; ++k) q.noalias() += a.block[k] * x.segment<3>(3 * a.column[k]);
  return q;
}

// Constrained blocks of the implicit system: block `block`'s component along the unit
// `normal` is fixed (Baraff and Witkin's filter S = I - n n^T there, the identity elsewhere)
struct Filter {
  int block;
  Vec3 normal;
  bool full;  // every direction fixed (S = 0 there)
  Mat3 held() const { return full ? Mat3(Mat3::Identity()) : Mat3(normal * normal.transpose()); }  // I - S
};

void apply_filter(const std::vector<Filter>& filter, Eigen::VectorXd& x) {
  for (const Filter& f : filter) {
    auto block = x.segment<3>(3 * f.block);
    if (f.full) {
      block.setZero();
    } else {
      block -= f.normal * f.normal.dot(block);
    }
  }
}

// each of `blocks` blocks' filter (its index in `filter`), -1 where it has none
std::vector<int> filter_of(const std::vector<Filter>& filter, Eigen::Index blocks) {
  std::vector<int> which(blocks, -1);
  for (size_t f = 0; f < filter.size(); ++f) which[filter[f].block] = static_cast<int>(f);
  return which;
}

// a <- S a S + (I - S), S the filter's block-diagonal projector (identity off the filter)
void filter_system(const std::vector<Filter>& filter, Eigen::SparseMatrix<double>& a) {
  const std::vector<int> which = filter_of(filter, a.cols() / 3);
  const auto project = [&](int b) { return Mat3(Mat3::Identity() - filter[which[b]].held()); };
  cloth_detail::for_each_block(a, [&](int r, int c, auto& block) {
    if (which[r] < 0 && which[c] < 0) return;
    if (which[r] >= 0) block = project(r) * block;
    if (which[c] >= 0) block = block * project(c);
    if (r == c) block += filter[which[r]].held();
  });
}

// The rows of the system at the filter's blocks, kept before filter_system so that the
// constraints' impulses can be computed from A itself after the solve
struct HeldRows {
  std::vector<std::vector<std::pair<int, Vec3>>> rows;  // (filter) (column, the 3 rows' values there)
  HeldRows() = default;
  HeldRows(Eigen::SparseMatrix<double>& a, const std::vector<Filter>& filter) : rows(filter.size()) {
    const std::vector<int> which = filter_of(filter, a.cols() / 3);
    // row block r of a symmetric matrix is its column block r transposed
    cloth_detail::for_each_block(a, [&](int r, int c, auto& block) {
      if (which[c] < 0) return;
      for (int q = 0; q < 3; ++q) rows[which[c]].emplace_back(3 * r + q, Vec3(block.row(q)));
    });
  }
  // out -= A z for a z that is zero off the filter's blocks (by symmetry, A's columns there
  // are these rows)
  void subtract_product(const std::vector<Filter>& filter, const Eigen::VectorXd& z, Eigen::VectorXd& out) const {
    for (size_t f = 0; f < rows.size(); ++f) {
      const Vec3 held = z.segment<3>(3 * filter[f].block);
      for (const auto& [column, values] : rows[f]) out[column] -= values.dot(held);
    }
  }
  // (A z) at filter f's block
  Vec3 product(size_t f, const Eigen::VectorXd& z) const {
    Vec3 sum = Vec3::Zero();
    for (const auto& [column, values] : rows[f]) sum += values * z[column];
    return sum;
  }
};

// Preconditioned conjugate gradients on the system p was last updated with (p.matrix(),
// multiplied by its lower triangle in single precision when the tolerance allows), until
// |b - A z| < tolerance |b| or kMaxSolverIterations;
// returns the iterations, counted as Eigen's ConjugateGradient counts them (the products
// after the first). The vector operations of each iteration are fused into two passes (the
// product with the step's dot product, the update with the residual's norm); everything
// runs in a fixed order, so the result has the same bits on any thread.
// With constrained blocks (Baraff and Witkin's modified PCG), z arrives holding its fixed
// components (zero elsewhere) and r the residual b - A z of them, A as it was before the
// filter (the filtered system no longer couples the held directions to the rest, but their
// fixed values must still drive it); every search direction and residual is filtered, so
// those components stay as they are and the rest solves the system in the remaining
// directions; the preconditioner becomes S P^-1 S, still symmetric. Without, z arrives zero
// and r = b.
int conjugate_gradients(const cloth_detail::Preconditioner& p, const Eigen::VectorXd& b, double tolerance,
                        Eigen::VectorXd& z, Eigen::VectorXd r, const std::vector<Filter>& filter) {
  const cloth_detail::BlockMatrix& a = p.matrix();
  const Eigen::Index size = b.size();
  const bool single = tolerance >= kSinglePrecisionTolerance;
  // q = A d and d . q (d is filtered, so d . S q = d . q): from the lower triangle in single
  // precision (multigrid.h), or row by row in double
  const auto multiply = [&](const Eigen::VectorXd& d, Eigen::VectorXd& q) {
    if (single) return cloth_detail::lower_product(a, d, q);
    double dq = 0.0;
    for (int i = 0; i < a.size; ++i) {
      q.segment<3>(3 * i) = block_row_product(a, d, i);
      dq += q.segment<3>(3 * i).dot(d.segment<3>(3 * i));
    }
    return dq;
  };
  apply_filter(filter, r);
  Eigen::VectorXd filtered_b = b;
  apply_filter(filter, filtered_b);
  const double goal = tolerance * tolerance * std::max(filtered_b.squaredNorm(), r.squaredNorm());
  if (goal == 0.0) return 0;
  Eigen::VectorXd direction, product(size), s;
  p.apply(r, direction);
  apply_filter(filter, direction);
  double rs = r.dot(direction);
  for (int iteration = 0; iteration < kMaxSolverIterations; ++iteration) {
    const double dq = multiply(direction, product);
    apply_filter(filter, product);
    const double alpha = rs / dq;
    double r2 = 0.0;
    for (Eigen::Index k = 0; k < size; ++k) {
      z[k] += alpha * direction[k];
      r[k] -= alpha * product[k];
      r2 += r[k] * r[k];
    }
    if (r2 < goal) return iteration;
    p.apply(r, s);
    apply_filter(filter, s);
    const double previous = rs;
    rs = r.dot(s);
    const double beta = rs / previous;
    for (Eigen::Index k = 0; k < size; ++k) direction[k] = s[k] + beta * direction[k];
  }
  return kMaxSolverIterations;
}

// The velocity a constraint leaves its vertex with, from `v`: the normal component set, and
// with stick the rest too
Vec3 constrained_velocity(const ClothContactConstraint& c, const Vec3& v) {
  const Vec3 across = c.stick ? Vec3(c.surface_velocity - c.normal * c.normal.dot(c.surface_velocity))
                              : Vec3(v - c.normal * c.normal.dot(v));
  return across + c.speed * c.normal;
}

// Damping, -damping H_m(x_mid) v, with its matrix weight x H_m when asked: H_m evaluated at
// the midpoint x + dt/2 v of the coming step, in the same pass over the elements as the
// elastic terms (Assembly::material_at). For a rigid rotation by an angle a per step, the
// edge-length rate that damping sees is then O(a^3) of the rotation's own velocities; at x
// or at x + dt v it would be O(a), which times a large stiffness visibly slows spins.
void set_damping(double damping, const Points& v, const Points& midpoint, double matrix_weight,
                 cloth_detail::Assembly& what) {
  if (damping == 0.0) return;
  what.velocity = &v;
  what.damping = damping;
  what.material_weight = matrix_weight;
  what.material_at = &midpoint;
}

// symplectic Euler: v += dt M^-1 (f_elastic + f_damping) + dt g; a constrained vertex's
// velocity along its normal is then set (explicit steps are short: the rest of the cloth
// answers in the next steps)
void explicit_velocities(const ClothModel& model, ClothData& data, double dt, const Vec3& gravity,
                         std::vector<ClothContactConstraint>* constraints) {
  Eigen::VectorXd force = Eigen::VectorXd::Zero(3 * static_cast<int>(data.x.rows()));
  cloth_detail::Assembly what;
  what.force = &force;
  const Points midpoint = data.x + (0.5 * dt) * data.v;
  set_damping(model.material.damping, data.v, midpoint, 0.0, what);
  model.forces->assemble(data.x, what);
  for (int k = 0; k < static_cast<int>(data.x.rows()); ++k) {
    if (model.pinned[k]) continue;
    data.v.row(k) += dt * (force.segment<3>(3 * k) / model.mass[k] + gravity).transpose();
  }
  if (!constraints) return;
  for (ClothContactConstraint& c : *constraints) {
    if (model.pinned[c.vertex]) continue;
    const Vec3 before = row(data.v, c.vertex), after = constrained_velocity(c, before);
    data.v.row(c.vertex) = after.transpose();
    const Vec3 impulse = model.mass[c.vertex] * (after - before);
    c.impulse = impulse.dot(c.normal);
    c.friction = impulse - c.impulse * c.normal;
  }
}

// The implicit system A z = b of one step, over the free vertices, scaled by M^-1/2 on both
// sides (unknown z = M^1/2 dv), so that the residual is measured in the norm that bounds the
// velocity error in kinetic-energy terms, |e|_M <= |r|_(M^-1): A into solver.system, b into
// rhs, M^-1/2 into scale. Elastic forces at the prediction and their Hessian, damping at the
// midpoint
void assemble_system(const ClothModel& model, const ClothData& data, ClothSolver& solver, double dt,
                     const Vec3& gravity, Eigen::VectorXd& rhs, Eigen::VectorXd& scale) {
  const int n = static_cast<int>(data.x.rows());
  Eigen::SparseMatrix<double>& system = solver.system;
  if (system.rows() == 0) system = model.pattern->make_matrix();
  system.coeffs().setZero();
  Eigen::VectorXd force = Eigen::VectorXd::Zero(3 * n);
  const Points predicted = data.x + dt * data.v;
  const Points midpoint = data.x + (0.5 * dt) * data.v;
  cloth_detail::Assembly what;
  what.hessian_weight = dt * dt;
  what.force = &force;
  what.pattern = model.pattern.get();
  what.matrix = &system;
  set_damping(model.material.damping, data.v, midpoint, model.material.damping * dt, what);
  model.forces->assemble(predicted, what);
  // the mass diagonal and the right-hand side, over free vertices only
  rhs.resize(3 * model.free_count);
  scale.resize(3 * model.free_count);
  for (int k = 0; k < n; ++k) {
    const int i = model.free_index[k];
    if (i < 0) continue;
    for (int r = 0; r < 3; ++r) {
      system.coeffRef(3 * i + r, 3 * i + r) += model.mass[k];
      scale[3 * i + r] = 1.0 / std::sqrt(model.mass[k]);
      rhs[3 * i + r] = dt * (force[3 * k + r] + model.mass[k] * gravity[r]) * scale[3 * i + r];
    }
  }
  for (int col = 0; col < system.outerSize(); ++col) {
    for (Eigen::SparseMatrix<double>::InnerIterator it(system, col); it; ++it) it.valueRef() *= scale[it.row()] * scale[col];
  }
}

// The constrained blocks, each fixed at z = M^1/2 dv along its normal (or in full): their
// filter, z holding the fixed components, the residual rhs - A z of them, A's rows there kept
// (held_rows) and the system filtered. The preconditioner is built from the filtered system
// S A S + (I - S) (S = I - n n^T, or 0, at a constrained block; multigrid.h): the conjugate
// gradients search only S's directions, where it equals A, and multigrid's coarse levels then
// see the held directions neither coupled to the rest nor stiff (unfiltered, as in Baraff and
// Witkin's own scheme, its coarse corrections go mostly into the held directions and the
// solve takes several times the iterations)
void constrain_system(const ClothModel& model, const ClothData& data, const std::vector<ClothContactConstraint>& constraints,
                      const Eigen::VectorXd& scale, Eigen::SparseMatrix<double>& system, std::vector<Filter>& filter,
                      Eigen::VectorXd& z, HeldRows& held_rows, Eigen::VectorXd& residual) {
  for (const ClothContactConstraint& c : constraints) {
    const int i = model.free_index[c.vertex];
    if (i < 0) continue;
    require(std::abs(c.normal.norm() - 1.0) < 1e-9, "constraint: normal must be a unit vector");
    filter.push_back({i, c.normal, c.stick});
    z.segment<3>(3 * i) = (constrained_velocity(c, row(data.v, c.vertex)) - row(data.v, c.vertex)) / scale[3 * i];
  }
  std::sort(filter.begin(), filter.end(), [](const Filter& a, const Filter& b) { return a.block < b.block; });
  for (size_t f = 1; f < filter.size(); ++f) require(filter[f].block != filter[f - 1].block, "constraint: one per vertex");
  held_rows = HeldRows(system, filter);
  held_rows.subtract_product(filter, z, residual);
  filter_system(filter, system);
}

// The surfaces' impulses on the constrained vertices: (A dv - b) in the held directions,
// unscaled (A dv - b = M^1/2 (A_s z - b_s)), from A's rows there as they were before the filter
void constraint_impulses(const ClothModel& model, const std::vector<Filter>& filter, const HeldRows& held_rows,
                         const Eigen::VectorXd& z, const Eigen::VectorXd& rhs, const Eigen::VectorXd& scale,
                         std::vector<ClothContactConstraint>& constraints) {
  std::vector<Vec3> impulse(model.free_count, Vec3::Zero());
  for (size_t f = 0; f < filter.size(); ++f) {
    const int i = filter[f].block;
    impulse[i] = filter[f].held() * (held_rows.product(f, z) - rhs.segment<3>(3 * i)) / scale[3 * i];
  }
  for (ClothContactConstraint& c : constraints) {
    const int i = model.free_index[c.vertex];
    if (i < 0) continue;
    c.impulse = impulse[i].dot(c.normal);
    c.friction = impulse[i] - c.impulse * c.normal;
  }
}

// linearized backward Euler (Baraff-Witkin), the elastic part linearized about the inertial
// prediction y = x + dt v, damping at the step's midpoint:
// (M + dt^2 H(y) + damping dt H_m(x_mid)) dv = dt (f(y) - damping H_m(x_mid) v + M g)
// With contact constraints (see ClothContactConstraint), the unknowns' components along
// their normals are fixed and the conjugate gradients filtered (conjugate_gradients).
void implicit_velocities(const ClothModel& model, ClothData& data, ClothSolver& solver, double dt, const Vec3& gravity,
                         std::vector<ClothContactConstraint>* constraints) {
  if (model.free_count == 0) return;
  const int n = static_cast<int>(data.x.rows());
  Eigen::VectorXd rhs, scale;
  assemble_system(model, data, solver, dt, gravity, rhs, scale);
  // conjugate gradients (preconditioned: cloth/multigrid.h), started from zero: a truncated
  // solve then errs towards a smaller response, never adding energy (started from the last
  // step's solution, its error follows the last step's, and a spinning, strongly damped cloth
  // gains energy)
  if (solver.preconditioner.use_count() > 1) solver.preconditioner = solver.preconditioner->clone();
  const double solve_start = thread_cpu_seconds();
  std::vector<Filter> filter;
  Eigen::VectorXd z = Eigen::VectorXd::Zero(3 * model.free_count);
  HeldRows held_rows;
  Eigen::VectorXd residual = rhs;  // rhs - A z
  if (constraints) constrain_system(model, data, *constraints, scale, solver.system, filter, z, held_rows, residual);
  solver.preconditioner->update(solver.system);
  solver.iterations += conjugate_gradients(*solver.preconditioner, rhs, model.tolerance, z, residual, filter);
  solver.seconds += thread_cpu_seconds() - solve_start;
  if (constraints) constraint_impulses(model, filter, held_rows, z, rhs, scale, *constraints);
  Eigen::VectorXd dv = scale.asDiagonal() * z;
  // With no vertex pinned or held the exact dv changes the total momentum by exactly dt M g
  // (the internal forces sum to zero); the solver's residual need not, so its net part is removed
  if (model.free_count == n && filter.empty()) {
    const double total_mass = model.mass.sum();
    Vec3 excess = -dt * total_mass * gravity;
    for (int k = 0; k < n; ++k) excess += model.mass[k] * dv.segment<3>(3 * k);
    const Vec3 correction = excess / total_mass;
    for (int k = 0; k < n; ++k) dv.segment<3>(3 * k) -= correction;
  }
  for (int k = 0; k < n; ++k) {
    const int i = model.free_index[k];
    if (i >= 0) data.v.row(k) += dv.segment<3>(3 * i).transpose();
  }
}

}  // namespace

ClothSolver make_solver(const ClothModel& m, ClothPreconditioner choice) {
  ClothSolver solver;
  const int n = static_cast<int>(m.rest.rows());
  // the implicit solve's preconditioner: multigrid over the free vertices' edge graph
  const bool multigrid = choice == ClothPreconditioner::kMultigrid ||
                         (choice == ClothPreconditioner::kAutomatic && m.free_count >= kMultigridVertices);
  if (m.integrator == ClothIntegrator::kImplicit && m.free_count > 0 && multigrid) {
    std::vector<std::vector<int>> graph(m.free_count);
    for (const cloth_detail::Edge& e : m.forces->edges()) {
      const int a = m.free_index[e.i], b = m.free_index[e.j];
      if (a < 0 || b < 0) continue;
      graph[a].push_back(b);
      graph[b].push_back(a);
    }
    Eigen::VectorXd scale(m.free_count);
    for (int v = 0; v < n; ++v) {
      if (m.free_index[v] >= 0) scale[m.free_index[v]] = std::sqrt(m.mass[v]);
    }
    solver.preconditioner = std::make_shared<cloth_detail::Multigrid>(m.pattern->make_matrix(), graph, scale);
  } else {
    solver.preconditioner = std::make_shared<cloth_detail::BlockJacobi>();
  }
  return solver;
}

bool uses_multigrid(const ClothSolver& solver) {
  return dynamic_cast<const cloth_detail::Multigrid*>(solver.preconditioner.get()) != nullptr;
}

void update_velocities(const ClothModel& model, ClothData& data, ClothSolver& solver, double dt, const Vec3& gravity,
                       std::vector<ClothContactConstraint>* constraints) {
  require(dt > 0.0 && std::isfinite(dt), "dt must be > 0");
  if (constraints) {
    for (ClothContactConstraint& c : *constraints) {
      require(c.vertex >= 0 && c.vertex < static_cast<int>(data.x.rows()), "constraint: vertex out of range");
      c.impulse = 0.0;
      c.friction.setZero();
    }
  }
  if (model.integrator == ClothIntegrator::kImplicit) {
    implicit_velocities(model, data, solver, dt, gravity, constraints);
  } else {
    explicit_velocities(model, data, dt, gravity, constraints);
  }
  // pinned vertices never move; attached ones keep the velocity their attachment gave them
  for (int k = 0; k < static_cast<int>(data.x.rows()); ++k) {
    if (model.pinned[k] && !model.attached[k]) data.v.row(k).setZero();
  }
}

void update_positions(const ClothModel& model, ClothData& data, double dt) {
  require(dt > 0.0 && std::isfinite(dt), "dt must be > 0");
  for (int k = 0; k < static_cast<int>(data.x.rows()); ++k) {
    if (model.pinned[k] && !model.attached[k]) {
      data.v.row(k).setZero();
    } else {
      data.x.row(k) += dt * data.v.row(k);
    }
  }
}

}  // namespace simbake
