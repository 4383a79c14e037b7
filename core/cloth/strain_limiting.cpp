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
#include "cloth/strain_limiting.h"

#include "cloth/cloth_forces.h"

#include <Eigen/Sparse>
#include <Eigen/SparseCholesky>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace simbake {

namespace {

constexpr int kStrainSweeps = 8;            // Gauss-Seidel sweeps of the strain limiter before the global pass
constexpr int kProjectionIterations = 10;   // most Newton iterations of the global pass
constexpr int kActiveSetPasses = 8;         // most active-set updates per Newton iteration
constexpr int kLineSearchHalvings = 30;     // of the global pass's step, at most, before it gives up
constexpr double kStrainTolerance = 1e-6;   // strain limiting is done when every edge is this close (x L)
constexpr double kEnforceThreshold = -1e-3; // kEnforce corrects edges compressed beyond this strain

void require(bool ok, const std::string& message) {
  if (!ok) throw std::invalid_argument("cloth: " + message);
}

Vec3 row(const Points& x, int k) { return x.row(k).transpose(); }

// The length an edge of rest length `rest` must have when its candidate length is `length`:
// (1 + limit) rest when stretched beyond that, rest under kEnforce when compressed beyond
// the threshold, or -1 when it is within its bounds
double strain_target(double length, double rest, double limit, bool enforce) {
  if (limit > 0.0 && length > (1.0 + limit) * rest) return (1.0 + limit) * rest;
  if (enforce && length < (1.0 + kEnforceThreshold) * rest) return rest;
  return -1.0;
}

// The strain limiter of one call: with the vertices marked in `held` (n, or null) held still
// besides the pinned ones (a held or pinned vertex's inverse mass is 0), and with `reaction`
// (n x 3, or null) the impulses each edge would have given its held (not pinned) end summed there
class StrainLimiter {
 public:
  StrainLimiter(const ClothModel& model, ClothData& data, const std::vector<char>* held, Points* reaction)
      : model_(model), data_(data), held_(held), reaction_(reaction), edges_(model.forces->edges()),
        limit_(model.material.strain_limit), enforce_(model.material.compression == CompressionMode::kEnforce) {}

  void limit(double dt, bool global) {
    require(dt > 0.0 && std::isfinite(dt), "dt must be > 0");
    if (model_.material.strain_limit <= 0.0 && model_.material.compression != CompressionMode::kEnforce) return;
    // Gauss-Seidel sweeps with the true masses, forward and backward in turn (momentum is
    // kept: every impulse is internal); usually a few are enough
    for (int sweep = 0; sweep < kStrainSweeps; ++sweep) {
      if (this->sweep(dt, sweep % 2 == 0 ? model_.forward_order : model_.backward_order) < kStrainTolerance) return;
    }
    // They converge slowly where a long chain of edges holds a load (a soft cloth hanging
    // from pins by its strain limit: a correction diffuses about one edge per sweep, and a
    // 12 x 12 cloth can need hundreds of sweeps). The rest is solved for all edges at once.
    if (global) project(dt);
  }

 private:
  double inverse_mass(int k) const { return held_ && (*held_)[k] ? 0.0 : model_.inverse_mass[k]; }
  double sweep(double dt, const std::vector<int>& order);
  void project(double dt);
  bool solve_active_set(const Points& p, const std::vector<double>& length, std::vector<double>& target, Points& move,
                        Points& pushed) const;
  double bound_violation(const Points& p) const;

  const ClothModel& model_;
  ClothData& data_;
  const std::vector<char>* held_;
  Points* reaction_;
  const std::vector<cloth_detail::Edge>& edges_;
  const double limit_;
  const bool enforce_;
};

// One Gauss-Seidel sweep over the edges in the given order: each edge off its target gets
// the impulse along it that puts its candidate length x + dt v exactly at the target,
// equal and opposite, shared by the inverse masses. Returns the largest correction made
// (relative to the rest length).
double StrainLimiter::sweep(double dt, const std::vector<int>& order) {
  const std::vector<cloth_detail::Edge>& edges = edges_;
  const double limit = limit_;
  const bool enforce = enforce_;
  const Points& x = data_.x;
  Points& v = data_.v;
  Points* reaction = reaction_;
  double worst = 0.0;
  for (int q : order) {
    const cloth_detail::Edge& e = edges[q];
    const double wi = inverse_mass(e.i), wj = inverse_mass(e.j);
    if (wi + wj == 0.0) continue;
    const Vec3 d = row(x, e.j) + dt * row(v, e.j) - row(x, e.i) - dt * row(v, e.i);
    const double length = d.norm();
    const double target = strain_target(length, e.rest, limit, enforce);
    if (target < 0.0 || length <= 0.0) continue;
    worst = std::max(worst, std::abs(length - target) / e.rest);
    const double excess = std::clamp(length - target, -model_.max_correction, model_.max_correction);
    const Vec3 change = (excess / (dt * (wi + wj) * length)) * d;
    v.row(e.i) += (wi * change).transpose();
    v.row(e.j) -= (wj * change).transpose();
    if (reaction && wi == 0.0 && !model_.pinned[e.i]) reaction->row(e.i) += change.transpose();
    if (reaction && wj == 0.0 && !model_.pinned[e.j]) reaction->row(e.j) -= change.transpose();
  }
  return worst;
}

// Strain limiting for all edges at once: Newton iterations on the candidate lengths (the
// "fast projection" of Goldenthal et al. 2007, with inequality bounds). With J the length
// Jacobian of the active edges at the candidate positions p = x + dt v and W = M^-1 (0 for
// pinned vertices), the edge impulses mu solve (J W J^T + eps) mu = -(lengths - targets)
// and change v by W J^T mu / dt: along each edge, equal and opposite, mass-weighted, as in a
// sweep. An edge is active while it violates its bound, and stays active (held at the
// bound) until its impulse would have to push the wrong way (apart for a stretched edge).
void StrainLimiter::project(double dt) {
  const std::vector<cloth_detail::Edge>& edges = edges_;
  const int count = static_cast<int>(edges.size()), n = static_cast<int>(data_.x.rows());
  std::vector<double> target(count, -1.0);  // >= 0: the edge is active, held at this length
  for (int iteration = 0; iteration < kProjectionIterations; ++iteration) {
    const Points p = data_.x + dt * data_.v;
    // lengths now; new violations become active; the largest error decides whether to go on
    std::vector<double> length(count);
    double worst = 0.0, violation = 0.0;  // the largest error (x L), and the errors' squares summed (the line search's)
    for (int q = 0; q < count; ++q) {
      const cloth_detail::Edge& e = edges[q];
      if (inverse_mass(e.i) + inverse_mass(e.j) == 0.0) continue;
      length[q] = (row(p, e.j) - row(p, e.i)).norm();
      const double bound = strain_target(length[q], e.rest, limit_, enforce_);
      if (bound >= 0.0) {
        target[q] = bound;
        worst = std::max(worst, std::abs(length[q] - bound) / e.rest);
        violation += (length[q] - bound) * (length[q] - bound);
      }
    }
    if (worst < kStrainTolerance) return;
    // solve on the active set; drop edges whose impulse has the wrong sign and re-solve
    Points move, pushed;
    for (int attempt = 0; attempt < kActiveSetPasses; ++attempt) {
      if (!solve_active_set(p, length, target, move, pushed)) break;
    }
    // the impulses, the step halved while it would leave the edges further past their bounds
    // than they are (their summed squares): linearized far from the bounds, over active edges
    // that are nearly redundant, a Newton step can overshoot wildly (a corner slamming into
    // the ground, friction stopping a vertex while its neighbours still move fast, sends it
    // off with the whole overshoot);
    // ClothStrainLimit.GlobalPassNeverLeavesTheEdgesFurtherPastTheirBounds has sheets like it
    double scale = 1.0;
    for (int halving = 0; bound_violation(p + scale * move) > violation; ++halving) {
      if (halving == kLineSearchHalvings) return;  // no step helps: the sweeps have done what they could
      scale *= 0.5;
    }
    for (int k = 0; k < n; ++k) data_.v.row(k) += (scale * move.row(k)) / dt;
    if (reaction_) *reaction_ += (scale / dt) * pushed;
  }
}

// One solve of the global pass on the active set (the edges with target >= 0) at the
// candidates p: the edge impulses mu, the position change `move` they make (and `pushed`, the
// held ends' share of them, x dt); edges whose impulse has the wrong sign are dropped, and
// those the move would push past a bound join. True when the set changed (solve it again)
bool StrainLimiter::solve_active_set(const Points& p, const std::vector<double>& length, std::vector<double>& target,
                                     Points& move, Points& pushed) const {
  const std::vector<cloth_detail::Edge>& edges = edges_;
  const double limit = limit_;
  const bool enforce = enforce_;
  const int count = static_cast<int>(edges.size()), n = static_cast<int>(data_.x.rows());
  Points* reaction = reaction_;
  Eigen::VectorXd mu;
  std::vector<int> active;
  std::vector<Vec3> direction;
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
    error[a] = std::clamp(length[active[a]] - target[active[a]], -model_.max_correction, model_.max_correction);
    at_vertex[e.i].push_back({a, -1.0});
    at_vertex[e.j].push_back({a, 1.0});
  }
  // J W J^T: edges meeting at a free vertex k couple through w_k (s_a d_a) . (s_b d_b)
  std::vector<Eigen::Triplet<double>> triplets;
  double largest = 0.0;
  for (int k = 0; k < n; ++k) {
    const double w = inverse_mass(k);
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
    move.row(e.i) -= (inverse_mass(e.i) * mu[a] * direction[a]).transpose();
    move.row(e.j) += (inverse_mass(e.j) * mu[a] * direction[a]).transpose();
    if (reaction && inverse_mass(e.i) == 0.0 && !model_.pinned[e.i]) pushed.row(e.i) -= (mu[a] * direction[a]).transpose();
    if (reaction && inverse_mass(e.j) == 0.0 && !model_.pinned[e.j]) pushed.row(e.j) += (mu[a] * direction[a]).transpose();
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
  return changed;
}

// The sum over the edges (those with a free end) of the squared distance by which each is
// past its bound (strain_target) at candidate positions p, as project sums it
double StrainLimiter::bound_violation(const Points& p) const {
  const double limit = limit_;
  const bool enforce = enforce_;
  double sum = 0.0;
  for (const cloth_detail::Edge& e : edges_) {
    if (inverse_mass(e.i) + inverse_mass(e.j) == 0.0) continue;
    const double length = (row(p, e.j) - row(p, e.i)).norm();
    const double bound = strain_target(length, e.rest, limit, enforce);
    if (bound >= 0.0) sum += (length - bound) * (length - bound);
  }
  return sum;
}

}  // namespace

void limit_strain(const ClothModel& model, ClothData& data, double dt, bool global) {
  StrainLimiter(model, data, nullptr, nullptr).limit(dt, global);
}

Points limit_strain_holding(const ClothModel& model, ClothData& data, double dt, const std::vector<char>& held) {
  require(held.size() == model.pinned.size(), "held: one flag per vertex");
  Points reaction = Points::Zero(data.x.rows(), 3);
  StrainLimiter(model, data, &held, &reaction).limit(dt, true);
  return reaction;
}

double candidate_strain(const ClothModel& model, const ClothData& data, double dt) {
  double strain = 0.0;
  for (const cloth_detail::Edge& e : model.forces->edges()) {
    const Vec3 d = row(data.x, e.j) + dt * row(data.v, e.j) - row(data.x, e.i) - dt * row(data.v, e.i);
    strain = std::max(strain, d.norm() / e.rest - 1.0);
  }
  return strain;
}

}  // namespace simbake
