// Cloth: in-plane elasticity (springs or a StVK membrane), bending, damping, implicit or
// explicit integration, strain limiting. The element code is in cloth_forces.cpp.
//
// In-plane elasticity, two models behind one interface (material.model):
//  * springs (the notes, "Curve / Springs"): every mesh edge is a spring, so a grid's
//    sides resist stretch and its triangle diagonals resist shear. Per edge of rest length
//    L, A = (x_j - x_i) / L is the deformation gradient of the segment and
//        W = 1/2 E (|A| - 1)^2 L,     f_j = -E (|x_j - x_i| / L - 1) d = -f_i,
//    d the unit edge direction: a spring of constant k = E / L. E (N, force per unit
//    strain) is not the user's number: stretch_stiffness is the sheet's stiffness Y (N/m,
//    as for the membrane) and each edge gets E = 12/5 Y a / L, a its share of the rest area
//    (a third of each of its triangles), i.e. the width of sheet it stands for. A refined
//    mesh is then the same sheet, and a regular right-triangle grid pulled along an axis
//    resists with exactly Y (its sides give 1/3 and its diagonals 1/12 of Y a / L's
//    stiffness: 5/12); an equilateral mesh gives 0.8 Y in every direction.
//  * membrane (the notes, "Elastic Surfaces" to "Surface elasticity"): each triangle is a
//    linear element; its rest shape is laid out in its own 2D frame (Dm, 2x2) so that the
//    deformation gradient F = Ds Dm^-1 is 3x2 (Ds = [x1 - x0, x2 - x0]), the Green strain
//    G = 1/2 (F^T F - I) is 2x2, and St. Venant-Kirchhoff gives
//        W = A0 (mu G:G + lambda/2 tr(G)^2),   S = 2 mu G + lambda tr(G) I,   P = F S,
//        forces on (x1, x2) = -A0 P Dm^-T (columns), on x0 minus their sum,
//    with plane-stress Lame parameters from Y = stretch_stiffness (Young's modulus x
//    thickness, N/m) and nu = poisson_ratio: mu = Y / (2 (1 + nu)), lambda = Y nu / (1 - nu^2),
//    so that a sheet pulled one way with free sides carries S11 = Y G11 and narrows by
//    G22 = -nu G11.
// Compression (notes, "Compression and buckling", Choi and Ko 2002's subgrid idea): real cloth
// buckles instead of compressing, which a coarse mesh cannot resolve. With kSubgrid (and
// kEnforce) a spring under compression (|A| < 1) has stiffness E x subgrid_scale; the
// membrane does the same per principal Green strain (W = mu sum s(g_i) g_i^2 + lambda/2
// s(tr G) tr(G)^2, s = subgrid_scale for a negative argument, else 1), so a sheet compressed
// one way and stretched the other only resists the stretch. kNone is symmetric.
// kEnforce adds an impulse pass (below) that keeps edges from shortening at all.
//
// Bending (notes, "Bending energy"; Grinspun, Hirani, Desbrun and Schroeder 2003, "Discrete
// shells"): for each interior edge (hinge) e with current dihedral angle theta, rest angle
// theta0 (of the rest mesh, so a curved rest mesh keeps its shape), rest length |e| and the
// rest areas A1, A2 of its two triangles,
//        W_e = c B (theta - theta0)^2 |e|^2 / (A1 + A2),     c = 1/2 (not the 3/2 of the paper).
// The constant is set so that the energy of a cylinder matches the continuum 1/2 B (1/R1 +
// 1/R2)^2 = B / (2 R^2) per unit area (cloth bends isometrically, so this is the case that
// matters). Derivation: for a regular mesh bent onto a cylinder of radius R, the hinges
// along the axis between strips of width h turn by theta = h / R and the others stay flat
// (exactly so on a grid with the axis along a grid direction; on an equilateral mesh the
// sum over the three edge directions gives the same, for any axis direction). Per unit
// area there is one axial hinge per h x a, with |e|^2 / (A1 + A2) = a^2 / (a h), so the
// energy per area is c B (h/R)^2 (a / h) / (h a) = c B / R^2: c = 1/2. More generally, on
// an equilateral mesh the edge sum has the density c (H2 - 8/3 K), H2 = (1/R1 + 1/R2)^2
// and K the Gaussian curvature, whatever the orientation; the paper's 3/2 makes the H2 term
// 3x too stiff (it is calibrated on a sphere, where the K term takes the excess back). With
// 1/2 the H2 term is exact and the K term, whose integral is topological (Gauss-Bonnet),
// exerts no force inside the sheet; cloth bends nearly isometrically (K ~ 0) anyway.
// Checked by the test ClothBending.CylinderEnergyConvergesToContinuum (grid and
// equilateral meshes; the error is the boundary's, ~1/n). Note: on a grid whose diagonals
// all run one way the energy of a cylinder depends on its direction (an anisotropy of the
// mesh, not of the constant): exact when the curvature runs along a grid axis or across the
// diagonals, 3x when it runs along them, 0.75x at the least (15 degrees off the axis).
// The dihedral angle's gradient is the closed form of Bridson, Marino and Fedkiw 2003
// ("Simulation of clothing with folds and wrinkles"): opposite vertex x2 gets -n_A / h_A,
// x3 gets -n_B / h_B, the edge's vertices the rest weighted by where x2, x3 project onto the
// edge. The force is -B (theta - theta0) |e|^2 / (A1 + A2) grad theta.
//
// Damping (notes, soft constraints with Rayleigh damping): f_d = -damping x H_m v, where
// H_m is the elastic Hessian's material (Gauss-Newton) part: for springs E/L d d^T, so only
// the relative velocity along the edge is damped; for the membrane (dG/dx)^T C (dG/dx) A0,
// i.e. the strain rate; for bending grad theta grad theta^T. Each is zero for any rigid
// motion (rigid velocities change no edge length, Green strain or dihedral angle at first
// order), so a freely spinning and translating cloth keeps its momentum and energy. (The
// full Hessian would not: its geometric part times a rotation is not zero under tension.)
// H_m is evaluated at the midpoint x + dt/2 v of the step, where the velocity the step
// uses is rigid to O(a^3) for a rotation by a per step (at x it would be O(a): enough,
// times a large stiffness, to brake a spinning cloth visibly).
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
// which the next step's stiff forces see in full (an 8 x 8 cloth with E = 20000 N spinning at
// 2 rad/s kept 1.4% of its kinetic energy after 1 s); about y it keeps 96.8%, backward
// Euler's own exp(-2 omega^2 dt t) whatever the stiffness. H is made positive
// semi-definite element by element (springs: the transverse term dropped under compression;
// membrane: the 9x9 Hessian projected by eigen-decomposition; bending: its Gauss-Newton part
// only), so M + dt^2 H + damping dt H_m is symmetric positive definite. It is assembled
// straight into an Eigen sparse matrix of fixed pattern (MatrixPattern, built once) over the
// unpinned vertices only (pinned rows and columns removed: their velocity is zero and stays
// so), elastic and damping terms in one pass over the elements, scaled by M^-1/2 on both
// sides, and solved by preconditioned conjugate gradients (our own loop, multiplying the
// preconditioner's 3x3-block copy of the matrix: 1.4x fewer bytes than Eigen's scalar one)
// to a relative residual `tolerance`, started from zero. The preconditioner (cloth/multigrid.h)
// is a smoothed-aggregation multigrid V-cycle, whose iteration count stays nearly flat as
// the mesh is refined, for cloths of 1,000 free vertices or more; small cloths keep
// block-Jacobi (its iterations grow as 1/h; see kMultigridVertices).
// (A sparse Cholesky factorization each step, SimplicialLDLT, was 10x slower on the 64 x 64
// drape; see benchmarks/cloth.)
// For a cloth with no pinned vertex, the net momentum error the solver leaves is removed
// (the exact solution changes the total momentum by dt M g only). Gravity is an external
// force m g on unpinned vertices.
// Explicit step: symplectic Euler, v += dt M^-1 f (positions then move with the new v).
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
// the bound can still go unstable over seconds through nonlinear coupling; at 0.8 of the
// bound it did not).
//
// Strain limiting (notes, "Strain limiting"; Provot 1995, Bridson et al. 2002): Gauss-Seidel
// sweeps over the edges; where the candidate positions x + dt v put an edge beyond (1 +
// limit) L, equal and opposite velocity impulses along it (shared by inverse mass, pinned
// vertices having none) bring its candidate length to exactly (1 + limit) L. kEnforce
// ("Enforced buckling") does the same for an edge whose candidate strain is below -0.001,
// bringing it back to L. A few sweeps usually suffice; where they do not (a load hanging
// on a long chain of limited edges, which Gauss-Seidel converges on only in hundreds of
// sweeps), the remaining violations are solved together, the same impulses computed by a
// sparse solve per Newton iteration (Goldenthal et al. 2007, "Efficient simulation of
// inextensible cloth", with an active set for the inequality). Both stop when every edge is
// within 1e-6 L of its bound. Impulses are internal, so momentum is kept.
#include "cloth/cloth.h"

#include "cloth/cloth_forces.h"
#include "cloth/multigrid.h"
#include "geometry/mesh.h"

#include <Eigen/SparseCholesky>
#include <Eigen/Sparse>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include <time.h>

namespace simbake {

namespace {

constexpr int kStrainSweeps = 8;            // Gauss-Seidel sweeps of the strain limiter before the global pass
constexpr int kProjectionIterations = 10;   // most Newton iterations of the global pass
constexpr int kActiveSetPasses = 8;         // most active-set updates per Newton iteration
constexpr int kLineSearchHalvings = 30;     // of the global pass's step, at most, before it gives up
constexpr double kStrainTolerance = 1e-6;   // strain limiting is done when every edge is this close (x L)
// The most an edge's length is corrected in one step, x the cloth's mean edge length. Far
// more than any step of a free cloth needs; it bounds the velocity the limiter can give
// where it fights a collision (cloth pushed by a keyed body against its own pins), which
// would otherwise grow without bound
constexpr double kMaxCorrection = 0.1;
constexpr double kEnforceThreshold = -1e-3; // kEnforce corrects edges compressed beyond this strain
constexpr double kStableSafety = 0.75;      // of the explicit stability bound
// the conjugate gradients multiply by the lower triangle in single precision (lower_kernels.h)
// when the solve's relative residual is this or looser: its rounding (1e-7 of each product)
// would show in a tighter solve. (Until the lower-triangle kernels, a system of under 1,000
// blocks multiplied in double: in cache, converting the floats cost more than reading them;
// the kernels convert four floats an instruction and read each block once for two rows, and
// the drape at 17 x 17 took 8% fewer instructions in single precision, callgrind)
constexpr double kSinglePrecisionTolerance = 1e-5;
constexpr int kMaxSolverIterations = 2000;  // conjugate gradient iterations per implicit step (at most)
constexpr int kMultigridVertices = 1000;    // automatic: multigrid from this many free vertices
// Automatic preconditioner: multigrid for a cloth of kMultigridVertices free vertices or more,
// block-Jacobi otherwise. On the drape multigrid takes 4-9x fewer iterations from 33 x 33 up,
// with a smaller profile error at 33-129; at 17 x 17 (289 vertices) block-Jacobi's cheaper
// iterations win, at no loss of accuracy there (benchmarks/results/cloth_solve_speed.md). The
// 81 mm it once let cloth_demo's heavy body press the cloth into the ground is gone since the
// pinch stage (0 mm over its 97 frames, block-Jacobi 1.2 mm). Pinned cloths kept block-Jacobi
// while a body's contact by the pins could hand its push to a free vertex of round-off weight
// (the flag died in its first step with multigrid); that contact is now bounded
// (contact/cloth_body_contact.cpp, kMaxLever).

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

// The length an edge of rest length `rest` must have when its candidate length is `length`:
// (1 + limit) rest when stretched beyond that, rest under kEnforce when compressed beyond
// the threshold, or -1 when it is within its bounds
double strain_target(double length, double rest, double limit, bool enforce) {
  if (limit > 0.0 && length > (1.0 + limit) * rest) return (1.0 + limit) * rest;
  if (enforce && length < (1.0 + kEnforceThreshold) * rest) return rest;
  return -1.0;
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

}  // namespace

namespace {

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

Cloth::Cloth(const ClothDesc& desc)
    : model_(std::make_shared<const ClothModel>(desc)), x_(desc.rest), v_(Points::Zero(desc.rest.rows(), 3)) {
  const ClothModel& m = *model_;
  const int n = vertex_count();
  // the implicit solve's preconditioner: multigrid over the free vertices' edge graph
  const bool multigrid = desc.preconditioner == ClothPreconditioner::kMultigrid ||
                         (desc.preconditioner == ClothPreconditioner::kAutomatic && m.free_count >= kMultigridVertices);
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
    preconditioner_ = std::make_shared<cloth_detail::Multigrid>(m.pattern->make_matrix(), graph, scale);
  } else {
    preconditioner_ = std::make_shared<cloth_detail::BlockJacobi>();
  }
}

// ---- stage: forces and the velocity update

void Cloth::update_velocities(double dt, const Vec3& gravity, std::vector<ClothContactConstraint>* constraints) {
  require(dt > 0.0 && std::isfinite(dt), "dt must be > 0");
  if (constraints) {
    for (ClothContactConstraint& c : *constraints) {
      require(c.vertex >= 0 && c.vertex < vertex_count(), "constraint: vertex out of range");
      c.impulse = 0.0;
      c.friction.setZero();
    }
  }
  if (model_->integrator == ClothIntegrator::kImplicit) {
    implicit_velocities(dt, gravity, constraints);
  } else {
    explicit_velocities(dt, gravity, constraints);
  }
  // pinned vertices never move
  for (int k = 0; k < vertex_count(); ++k) {
    if (model_->pinned[k]) v_.row(k).setZero();
  }
}

// symplectic Euler: v += dt M^-1 (f_elastic + f_damping) + dt g; a constrained vertex's
// velocity along its normal is then set (explicit steps are short: the rest of the cloth
// answers in the next steps)
void Cloth::explicit_velocities(double dt, const Vec3& gravity, std::vector<ClothContactConstraint>* constraints) {
  Eigen::VectorXd force = Eigen::VectorXd::Zero(3 * vertex_count());
  cloth_detail::Assembly what;
  what.force = &force;
  const Points midpoint = x_ + (0.5 * dt) * v_;
  set_damping(model_->material.damping, v_, midpoint, 0.0, what);
  model_->forces->assemble(x_, what);
  for (int k = 0; k < vertex_count(); ++k) {
    if (model_->pinned[k]) continue;
    v_.row(k) += dt * (force.segment<3>(3 * k) / model_->mass[k] + gravity).transpose();
  }
  if (!constraints) return;
  for (ClothContactConstraint& c : *constraints) {
    if (model_->pinned[c.vertex]) continue;
    const Vec3 before = row(v_, c.vertex), after = constrained_velocity(c, before);
    v_.row(c.vertex) = after.transpose();
    const Vec3 impulse = model_->mass[c.vertex] * (after - before);
    c.impulse = impulse.dot(c.normal);
    c.friction = impulse - c.impulse * c.normal;
  }
}

// linearized backward Euler (Baraff-Witkin), the elastic part linearized about the inertial
// prediction y = x + dt v, damping at the step's midpoint:
// (M + dt^2 H(y) + damping dt H_m(x_mid)) dv = dt (f(y) - damping H_m(x_mid) v + M g)
// With contact constraints (see ClothContactConstraint), the unknowns' components along
// their normals are fixed and the conjugate gradients filtered (conjugate_gradients).
void Cloth::implicit_velocities(double dt, const Vec3& gravity, std::vector<ClothContactConstraint>* constraints) {
  if (model_->free_count == 0) return;
  const int n = vertex_count();
  Eigen::SparseMatrix<double>& system = system_;
  if (system.rows() == 0) system = model_->pattern->make_matrix();
  system.coeffs().setZero();
  // elastic forces at the prediction and their Hessian, damping at the midpoint
  Eigen::VectorXd force = Eigen::VectorXd::Zero(3 * n);
  const Points predicted = x_ + dt * v_;
  const Points midpoint = x_ + (0.5 * dt) * v_;
  cloth_detail::Assembly what;
  what.hessian_weight = dt * dt;
  what.force = &force;
  what.pattern = model_->pattern.get();
  what.matrix = &system;
  set_damping(model_->material.damping, v_, midpoint, model_->material.damping * dt, what);
  model_->forces->assemble(predicted, what);
  // the mass diagonal and the right-hand side, over free vertices only; the system is
  // scaled by M^-1/2 on both sides (unknown z = M^1/2 dv), so that the residual is measured
  // in the norm that bounds the velocity error in kinetic-energy terms, |e|_M <= |r|_(M^-1)
  Eigen::VectorXd rhs(3 * model_->free_count), scale(3 * model_->free_count);
  for (int k = 0; k < n; ++k) {
    const int i = model_->free_index[k];
    if (i < 0) continue;
    for (int r = 0; r < 3; ++r) {
      system.coeffRef(3 * i + r, 3 * i + r) += model_->mass[k];
      scale[3 * i + r] = 1.0 / std::sqrt(model_->mass[k]);
      rhs[3 * i + r] = dt * (force[3 * k + r] + model_->mass[k] * gravity[r]) * scale[3 * i + r];
    }
  }
  for (int col = 0; col < system.outerSize(); ++col) {
    for (Eigen::SparseMatrix<double>::InnerIterator it(system, col); it; ++it) it.valueRef() *= scale[it.row()] * scale[col];
  }
  // conjugate gradients (preconditioned: cloth/multigrid.h), started from zero: a truncated solve
  // then errs towards a smaller response, never adding energy. (Started from the last
  // step's solution it took 16% fewer iterations on the drape, but its error follows the
  // last step's: a spinning, strongly damped cloth gained 3% kinetic energy at 1e-3.)
  if (preconditioner_.use_count() > 1) preconditioner_ = preconditioner_->clone();
  const double solve_start = thread_cpu_seconds();
  // the constrained blocks, each fixed at z = M^1/2 dv along its normal (or in full). The
  // preconditioner is built from the filtered system S A S + (I - S) (S = I - n n^T, or 0,
  // at a constrained block; multigrid.h): the conjugate gradients search only S's
  // directions, where it equals A, and multigrid's coarse levels then see the held
  // directions neither coupled to the rest nor stiff. On the drape at rest this takes 20%
  // fewer iterations than the previous preconditioner, A with each held direction made
  // stiff (+ 100 x its diagonal: 33 x 33 25 -> 19.5 iterations a step, 65 x 65 27.5 -> 23);
  // unfiltered (Baraff and Witkin's own scheme) it took 3.3x the iterations on the 33 x 33
  // drape, its coarse corrections going mostly into the held directions.
  std::vector<Filter> filter;
  Eigen::VectorXd z = Eigen::VectorXd::Zero(3 * model_->free_count);
  HeldRows held_rows;
  Eigen::VectorXd residual = rhs;  // rhs - A z
  if (constraints) {
    for (const ClothContactConstraint& c : *constraints) {
      const int i = model_->free_index[c.vertex];
      if (i < 0) continue;
      require(std::abs(c.normal.norm() - 1.0) < 1e-9, "constraint: normal must be a unit vector");
      filter.push_back({i, c.normal, c.stick});
      z.segment<3>(3 * i) = (constrained_velocity(c, row(v_, c.vertex)) - row(v_, c.vertex)) / scale[3 * i];
    }
    std::sort(filter.begin(), filter.end(), [](const Filter& a, const Filter& b) { return a.block < b.block; });
    for (size_t f = 1; f < filter.size(); ++f) require(filter[f].block != filter[f - 1].block, "constraint: one per vertex");
    held_rows = HeldRows(system, filter);
    held_rows.subtract_product(filter, z, residual);
    filter_system(filter, system);
  }
  preconditioner_->update(system);
  solver_iterations_ += conjugate_gradients(*preconditioner_, rhs, model_->tolerance, z, residual, filter);
  solver_seconds_ += thread_cpu_seconds() - solve_start;
  if (constraints) {
    // the surfaces' impulses: (A dv - b) in the held directions, unscaled (A dv - b =
    // M^1/2 (A_s z - b_s)), from A's rows there as they were before the filter
    std::vector<Vec3> impulse(model_->free_count, Vec3::Zero());
    for (size_t f = 0; f < filter.size(); ++f) {
      const int i = filter[f].block;
      impulse[i] = filter[f].held() * (held_rows.product(f, z) - rhs.segment<3>(3 * i)) / scale[3 * i];
    }
    for (ClothContactConstraint& c : *constraints) {
      const int i = model_->free_index[c.vertex];
      if (i < 0) continue;
      c.impulse = impulse[i].dot(c.normal);
      c.friction = impulse[i] - c.impulse * c.normal;
    }
  }
  Eigen::VectorXd dv = scale.asDiagonal() * z;
  // With no vertex pinned or held the exact dv changes the total momentum by exactly dt M g
  // (the internal forces sum to zero); the solver's residual need not, so its net part is removed
  if (model_->free_count == n && filter.empty()) {
    const double total_mass = model_->mass.sum();
    Vec3 excess = -dt * total_mass * gravity;
    for (int k = 0; k < n; ++k) excess += model_->mass[k] * dv.segment<3>(3 * k);
    const Vec3 correction = excess / total_mass;
    for (int k = 0; k < n; ++k) dv.segment<3>(3 * k) -= correction;
  }
  for (int k = 0; k < n; ++k) {
    const int i = model_->free_index[k];
    if (i >= 0) v_.row(k) += dv.segment<3>(3 * i).transpose();
  }
}

bool Cloth::uses_multigrid() const {
  return dynamic_cast<const cloth_detail::Multigrid*>(preconditioner_.get()) != nullptr;
}

// ---- stage: strain limiting (and enforced buckling) by impulses along edges

// One Gauss-Seidel sweep over the edges in the given order: each edge off its target gets
// the impulse along it that puts its candidate length x + dt v exactly at the target,
// equal and opposite, shared by the inverse masses. Returns the largest correction made
// (relative to the rest length).
double Cloth::strain_sweep(double dt, const std::vector<int>& order, const std::vector<char>* held, Points* reaction) {
  const std::vector<cloth_detail::Edge>& edges = model_->forces->edges();
  const double limit = model_->material.strain_limit;
  const bool enforce = model_->material.compression == CompressionMode::kEnforce;
  double worst = 0.0;
  for (int q : order) {
    const cloth_detail::Edge& e = edges[q];
    const double wi = inverse_mass(e.i, held), wj = inverse_mass(e.j, held);
    if (wi + wj == 0.0) continue;
    const Vec3 d = row(x_, e.j) + dt * row(v_, e.j) - row(x_, e.i) - dt * row(v_, e.i);
    const double length = d.norm();
    const double target = strain_target(length, e.rest, limit, enforce);
    if (target < 0.0 || length <= 0.0) continue;
    worst = std::max(worst, std::abs(length - target) / e.rest);
    const double excess = std::clamp(length - target, -model_->max_correction, model_->max_correction);
    const Vec3 change = (excess / (dt * (wi + wj) * length)) * d;
    v_.row(e.i) += (wi * change).transpose();
    v_.row(e.j) -= (wj * change).transpose();
    if (reaction && wi == 0.0 && !model_->pinned[e.i]) reaction->row(e.i) += change.transpose();
    if (reaction && wj == 0.0 && !model_->pinned[e.j]) reaction->row(e.j) -= change.transpose();
  }
  return worst;
}

void Cloth::limit_strain(double dt, bool global) { limit_strain(dt, global, nullptr, nullptr); }

void Cloth::limit_strain(double dt, bool global, const std::vector<char>* held, Points* reaction) {
  require(dt > 0.0 && std::isfinite(dt), "dt must be > 0");
  if (model_->material.strain_limit <= 0.0 && model_->material.compression != CompressionMode::kEnforce) return;
  // Gauss-Seidel sweeps with the true masses, forward and backward in turn (momentum is
  // kept: every impulse is internal); usually a few are enough
  for (int sweep = 0; sweep < kStrainSweeps; ++sweep) {
    if (strain_sweep(dt, sweep % 2 == 0 ? model_->forward_order : model_->backward_order, held, reaction) < kStrainTolerance) return;
  }
  // They converge slowly where a long chain of edges holds a load (a soft cloth hanging
  // from pins by its strain limit: a correction diffuses about one edge per sweep, and a
  // 12 x 12 cloth can need hundreds of sweeps). The rest is solved for all edges at once.
  if (global) project_strain(dt, held, reaction);
}

Points Cloth::limit_strain_holding(double dt, const std::vector<char>& held) {
  require(held.size() == model_->pinned.size(), "held: one flag per vertex");
  Points reaction = Points::Zero(vertex_count(), 3);
  limit_strain(dt, true, &held, &reaction);
  return reaction;
}

// Strain limiting for all edges at once: Newton iterations on the candidate lengths (the
// "fast projection" of Goldenthal et al. 2007, with inequality bounds). With J the length
// Jacobian of the active edges at the candidate positions p = x + dt v and W = M^-1 (0 for
// pinned vertices), the edge impulses mu solve (J W J^T + eps) mu = -(lengths - targets)
// and change v by W J^T mu / dt: along each edge, equal and opposite, mass-weighted, as in a
// sweep. An edge is active while it violates its bound, and stays active (held at the
// bound) until its impulse would have to push the wrong way (apart for a stretched edge).
void Cloth::project_strain(double dt, const std::vector<char>* held, Points* reaction) {
  const std::vector<cloth_detail::Edge>& edges = model_->forces->edges();
  const double limit = model_->material.strain_limit;
  const bool enforce = model_->material.compression == CompressionMode::kEnforce;
  const int count = static_cast<int>(edges.size()), n = vertex_count();
  std::vector<double> target(count, -1.0);  // >= 0: the edge is active, held at this length
  for (int iteration = 0; iteration < kProjectionIterations; ++iteration) {
    const Points p = x_ + dt * v_;
    // lengths now; new violations become active; the largest error decides whether to go on
    std::vector<double> length(count);
    double worst = 0.0, violation = 0.0;  // the largest error (x L), and the errors' squares summed (the line search's)
    for (int q = 0; q < count; ++q) {
      const cloth_detail::Edge& e = edges[q];
      if (inverse_mass(e.i, held) + inverse_mass(e.j, held) == 0.0) continue;
      length[q] = (row(p, e.j) - row(p, e.i)).norm();
      const double bound = strain_target(length[q], e.rest, limit, enforce);
      if (bound >= 0.0) {
        target[q] = bound;
        worst = std::max(worst, std::abs(length[q] - bound) / e.rest);
        violation += (length[q] - bound) * (length[q] - bound);
      }
    }
    if (worst < kStrainTolerance) return;
    // solve on the active set; drop edges whose impulse has the wrong sign and re-solve
    Eigen::VectorXd mu;
    std::vector<int> active;
    std::vector<Vec3> direction;
    Points move, pushed;
    for (int attempt = 0; attempt < kActiveSetPasses; ++attempt) {
      active.clear();
      for (int q = 0; q < count; ++q) {
        if (target[q] >= 0.0) active.push_back(q);
      }
      const int m = static_cast<int>(active.size());
      direction.assign(m, Vec3::Zero());
      std::vector<std::vector<std::pair<int, double>>> at_vertex(n);  // (active row, -1 first / +1 second end)
      Eigen::VectorXd error(m);
      for (int a = 0; a < m; ++a) {
        const cloth_detail::Edge& e = edges[active[a]];
        const Vec3 d = row(p, e.j) - row(p, e.i);
        if (length[active[a]] > 0.0) direction[a] = d / length[active[a]];
        error[a] = std::clamp(length[active[a]] - target[active[a]], -model_->max_correction, model_->max_correction);
        at_vertex[e.i].push_back({a, -1.0});
        at_vertex[e.j].push_back({a, 1.0});
      }
      // J W J^T: edges meeting at a free vertex k couple through w_k (s_a d_a) . (s_b d_b)
      std::vector<Eigen::Triplet<double>> triplets;
      double largest = 0.0;
      for (int k = 0; k < n; ++k) {
        const double w = inverse_mass(k, held);
        if (w == 0.0) continue;
        for (const auto& [a, sa] : at_vertex[k]) {
          for (const auto& [b, sb] : at_vertex[k]) {
            triplets.emplace_back(a, b, w * sa * sb * direction[a].dot(direction[b]));
          }
          largest = std::max(largest, w);
        }
      }
      // a whisker of compliance keeps it definite where active edges are redundant (a flat
      // triangle mesh has more edges than in-plane degrees of freedom)
      for (int a = 0; a < m; ++a) triplets.emplace_back(a, a, 1e-9 * largest);
      Eigen::SparseMatrix<double> system(m, m);
      system.setFromTriplets(triplets.begin(), triplets.end());
      Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(system);
      mu = solver.solve(Eigen::VectorXd(-error));
      // a stretched edge may only be pulled together (mu <= 0), a compressed one pushed apart
      bool changed = false;
      for (int a = 0; a < m; ++a) {
        const cloth_detail::Edge& e = edges[active[a]];
        const bool stretched = target[active[a]] > e.rest;
        const bool violated = stretched ? error[a] > 0.0 : error[a] < 0.0;
        if (!violated && (stretched ? mu[a] > 0.0 : mu[a] < 0.0)) {
          target[active[a]] = -1.0;
          changed = true;
        }
      }
      // the position change these impulses make, and the edges it would push past a bound
      // (to first order): they join, and the set is solved again
      // (and with `reaction`, the held ends' share of the impulses, x dt)
      move.setZero(n, 3);
      if (reaction) pushed.setZero(n, 3);
      for (int a = 0; a < m; ++a) {
        const cloth_detail::Edge& e = edges[active[a]];
        move.row(e.i) -= (inverse_mass(e.i, held) * mu[a] * direction[a]).transpose();
        move.row(e.j) += (inverse_mass(e.j, held) * mu[a] * direction[a]).transpose();
        if (reaction && inverse_mass(e.i, held) == 0.0 && !model_->pinned[e.i]) pushed.row(e.i) -= (mu[a] * direction[a]).transpose();
        if (reaction && inverse_mass(e.j, held) == 0.0 && !model_->pinned[e.j]) pushed.row(e.j) += (mu[a] * direction[a]).transpose();
      }
      const bool dropped = changed;
      for (int q = 0; q < count && !dropped; ++q) {
        if (target[q] >= 0.0 || length[q] <= 0.0) continue;
        const cloth_detail::Edge& e = edges[q];
        const Vec3 d = (row(p, e.j) - row(p, e.i)) / length[q];
        const double predicted = length[q] + d.dot(row(move, e.j) - row(move, e.i));
        const double bound = strain_target(predicted, e.rest, limit, enforce);
        if (bound >= 0.0) {
          target[q] = bound;
          changed = true;
        }
      }
      if (!changed) break;
    }
    // the impulses, the step halved while it would leave the edges further past their bounds
    // than they are (their summed squares): linearized far from the bounds, over active edges
    // that are nearly redundant, a Newton step can overshoot wildly. On the 257 x 257 drape
    // (a corner slamming into the ground, friction stopping a vertex while its neighbours
    // still moved at 6 m/s: 580% strain) one sent that vertex off at 57 m/s with 7,450%
    // strain, on a path that a change of round-off alone picked (README limitations);
    // ClothStrainLimit.GlobalPassNeverLeavesTheEdgesFurtherPastTheirBounds has sheets like it
    double scale = 1.0;
    for (int halving = 0; bound_violation(p + scale * move, held) > violation; ++halving) {
      if (halving == kLineSearchHalvings) return;  // no step helps: the sweeps have done what they could
      scale *= 0.5;
    }
    for (int k = 0; k < n; ++k) v_.row(k) += (scale * move.row(k)) / dt;
    if (reaction) *reaction += (scale / dt) * pushed;
  }
}

// The sum over the edges (those with a free end) of the squared distance by which each is
// past its bound (strain_target) at candidate positions p, as project_strain sums it
double Cloth::bound_violation(const Points& p, const std::vector<char>* held) const {
  const double limit = model_->material.strain_limit;
  const bool enforce = model_->material.compression == CompressionMode::kEnforce;
  double sum = 0.0;
  for (const cloth_detail::Edge& e : model_->forces->edges()) {
    if (inverse_mass(e.i, held) + inverse_mass(e.j, held) == 0.0) continue;
    const double length = (row(p, e.j) - row(p, e.i)).norm();
    const double bound = strain_target(length, e.rest, limit, enforce);
    if (bound >= 0.0) sum += (length - bound) * (length - bound);
  }
  return sum;
}

// ---- stage: positions

void Cloth::update_positions(double dt) {
  require(dt > 0.0 && std::isfinite(dt), "dt must be > 0");
  for (int k = 0; k < vertex_count(); ++k) {
    if (model_->pinned[k]) {
      v_.row(k).setZero();
    } else {
      x_.row(k) += dt * v_.row(k);
    }
  }
}

// ---- the explicit stability limit (derivation at the top of this file)

double Cloth::stable_explicit_step() const { return model_->stable_step; }

// ---- measurements

double Cloth::elastic_energy() const { return model_->forces->stretch_energy(x_) + model_->forces->bend_energy(x_); }

double Cloth::kinetic_energy() const {
  double e = 0.0;
  for (int k = 0; k < vertex_count(); ++k) e += 0.5 * model_->mass[k] * v_.row(k).squaredNorm();
  return e;
}

double Cloth::potential_energy(const Vec3& gravity) const {
  double e = 0.0;
  for (int k = 0; k < vertex_count(); ++k) e -= model_->mass[k] * gravity.dot(row(x_, k));
  return e;
}

double Cloth::max_strain() const {
  double strain = -1.0;
  for (const cloth_detail::Edge& e : model_->forces->edges()) {
    strain = std::max(strain, (row(x_, e.j) - row(x_, e.i)).norm() / e.rest - 1.0);
  }
  return strain;
}

double Cloth::candidate_strain(double dt) const {
  double strain = 0.0;
  for (const cloth_detail::Edge& e : model_->forces->edges()) {
    const Vec3 d = row(x_, e.j) + dt * row(v_, e.j) - row(x_, e.i) - dt * row(v_, e.i);
    strain = std::max(strain, d.norm() / e.rest - 1.0);
  }
  return strain;
}

Points Cloth::vertex_normals() const {
  TriangleMesh mesh;
  mesh.vertices = x_;
  mesh.triangles = model_->triangles;
  return simbake::vertex_normals(mesh);
}

}  // namespace simbake
