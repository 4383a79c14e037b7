// The joints stage: joints held by impulses on the bodies, in the spirit of the collision and
// contact stages (impulses change start-of-step velocities, and so where the step takes the
// bodies), with pre-stabilization as Weinstein, Teran and Fedkiw, "Dynamic simulation of
// articulated rigid bodies with contact and collision" (IEEE TVCG 2006) set it beside
// Guendelman et al. 2003's scheme.
//
// After gravity and the contacts, and before the position update, each joint's coordinates
// (joint_rows.h) are measured where the bodies' velocities now take them (x + dt v, the
// torque-free rotation of L: exactly what update_positions will do). The impulses lambda along
// the joints' rows solve, for every held coordinate C,
//     C(end of step) = target     (locked; a limit that would be passed: its bound)
// Linearized with the Jacobian J at the start of the step, dC = dt J M^-1 J^T dlambda, this is
// one sparse symmetric system A dlambda = -e / dt per connected set of jointed bodies (A = J
// M^-1 J^T, e the error at the end of the step), solved directly (sparse LDL^T), so long
// chains and mass ratios of 1000 are held as firmly as a single pendulum; a few Newton
// iterations (measure again, solve again) take the nonlinearity. The position constraint at
// the end of the step is the velocity scheme's SHAKE (Ryckaert et al. 1977): symplectic, so
// an undriven mechanism neither gains nor loses energy over time, and no drift accumulates:
// a chain does not open. Limits are one-sided rows (impulse >= 0 or <= 0) in an active set:
// one that would pull is let go. A drive is an implicit spring-damper, a row of compliance
// gamma = 1 / (dt (dt ks + kd)) whose impulse is bounded by max_force dt (a drive at its bound
// leaves the solve). A joint whose impulse over the step exceeds break_force dt (or
// break_torque dt) breaks, for good, at the end of the step.
//
// Components are found in joint order and solved in parallel; each writes only its own
// bodies and joints, so the result is the same bits on any number of threads.
#include "rigid/joints.h"

#include "rigid/sleeping.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

namespace simbake {

namespace {

constexpr int kIterations = 16;         // Newton iterations per step, at most
constexpr double kTolerance = 1e-10;    // (m, rad) error at which a step's solve stops early
constexpr double kDivergence = 1e-6;    // (m, rad) an error this small never counts as diverging
// relative to A's diagonal: where joints close a loop their rows are redundant, and stay
// solvable; a tree's are independent, and its tiny regularization only guards the pivots
// (any regularization slows Newton to a linear rate of about itself times A's condition,
// which a 50-link chain makes thousands)
constexpr double kLoopRegularization = 1e-5;
// a Newton step on the last factorization (its Jacobian a step old) is kept while it takes
// the error down at least this much; a slower one asks for a fresh factorization (a chord
// step costs a solve, a fresh one a factorization: a stricter rate refactors more often
// than the chord iterations it saves are worth, a looser one iterates longer)
constexpr double kChordRate = 0.2;
constexpr double kTreeRegularization = 1e-9;

bool dynamic_body(const RigidModel& model, int i) { return i != kWorldBody && !model.defs[i].kinematic; }

// Sleeping bodies jointed to an awake one or a moving kinematic body are woken; then the
// components of the awake jointed bodies, in the order of their first joint
void find_components(const RigidModel& model, RigidData& data, JointScratch& js) {
  const int n = model.body_count();
  const auto awake = [&](int i) {
    if (i == kWorldBody) return false;
    return model.defs[i].kinematic ? moving_kinematic(model, data, i) : data.asleep[i] == 0;
  };
  for (int j = 0; j < static_cast<int>(model.joints.size()); ++j) {
    if (!data.joints.enabled[j]) continue;
    const int b[2] = {model.joints[j].body0, model.joints[j].body1};
    for (int s = 0; s < 2; ++s) {
      if (dynamic_body(model, b[s]) && data.asleep[b[s]] && awake(b[1 - s])) wake_island(model, data, b[s]);
    }
  }
  reset_sets(js.parent, n);
  for (int j = 0; j < static_cast<int>(model.joints.size()); ++j) {
    const JointDef& def = model.joints[j];
    if (!data.joints.enabled[j] || !dynamic_body(model, def.body0) || !dynamic_body(model, def.body1)) continue;
    const int a = set_root(js.parent, def.body0), b = set_root(js.parent, def.body1);
    if (a != b) js.parent[std::max(a, b)] = std::min(a, b);
  }
  js.local.assign(n, -1);
  js.component_of.assign(n, -1);
  std::vector<int>& of_root = js.component_of;  // (first: the component of each root)
  js.count = 0;
  for (int j = 0; j < static_cast<int>(model.joints.size()); ++j) {
    const JointDef& def = model.joints[j];
    const int body = dynamic_body(model, def.body0) ? def.body0 : def.body1;
    if (!data.joints.enabled[j] || !dynamic_body(model, body) || data.asleep[body]) continue;
    const int root = set_root(js.parent, body);
    if (of_root[root] < 0) {
      of_root[root] = js.count++;
      if (static_cast<int>(js.components.size()) < js.count) js.components.emplace_back();
      js.components[of_root[root]].joints.clear();
      js.components[of_root[root]].bodies.clear();
    }
    js.components[of_root[root]].joints.push_back(j);
  }
  for (int i = 0; i < n; ++i) {
    if (!dynamic_body(model, i) || data.asleep[i]) continue;
    const int c = of_root[set_root(js.parent, i)];
    if (c < 0) continue;
    js.local[i] = static_cast<int>(js.components[c].bodies.size());
    js.components[c].bodies.push_back(i);
  }
}

struct ComponentSolver {
  const RigidModel& model;
  RigidData& data;
  const JointScratch& js;
  JointComponent& c;
  double h;

  // Body g's pose at the start of the step or where the step takes it (the world: the origin)
  BodyPose pose(int g, bool candidate) const {
    if (g == kWorldBody) return {};
    const int i = js.local[g];
    if (i >= 0) return candidate ? c.candidate[i] : c.start[i];
    if (!candidate) return {data.x[g], data.q[g]};
    return {data.x[g] + h * data.v[g], prescribed_rotation(data.q[g], data.spin[g], h)};
  }

  double inverse_mass(int i) const { return model.defs[c.bodies[i]].inverse_mass; }

  // J_r M^-1 J_s^T through local body i (0 when a row does not touch it)
  double coupling_at(const JointRow& r, const JointRow& s, int i) const {
    double sum = 0.0;
    for (int a = 0; a < 2; ++a) {
      for (int b = 0; b < 2; ++b) {
        if (r.side[a] != i || s.side[b] != i) continue;
        sum += inverse_mass(i) * r.linear[a].dot(s.linear[b]) + r.angular[a].dot(c.inverse_inertia[i] * s.angular[b]);
      }
    }
    return sum;
  }

  // J_r M^-1 J_s^T over every body
  double coupling(const JointRow& r, const JointRow& s) const {
    double sum = 0.0;
    for (int i : {r.side[0], r.side[1]}) {
      if (i >= 0) sum += coupling_at(r, s, i);
    }
    return sum;
  }

  // The row's rate J v now
  double rate(const JointRow& r) const {
    double u = 0.0;
    for (int s = 0; s < 2; ++s) {
      const int i = r.side[s];
      if (i < 0) continue;
      const int g = c.bodies[i];
      u += r.linear[s].dot(data.v[g]) + r.angular[s].dot(c.inverse_inertia[i] * data.l[g]);
    }
    return u;
  }

  void apply(JointRow& r, double impulse) {
    for (int s = 0; s < 2; ++s) {
      const int i = r.side[s];
      if (i < 0) continue;
      const int g = c.bodies[i];
      data.v[g] += inverse_mass(i) * impulse * r.linear[s];
      data.l[g] += impulse * r.angular[s];
    }
    r.impulse += impulse;
  }

  void begin() {
    const int nb = static_cast<int>(c.bodies.size());
    c.start.resize(nb);
    c.candidate.resize(nb);
    c.inverse_inertia.resize(nb);
    for (int i = 0; i < nb; ++i) {
      const int g = c.bodies[i];
      c.start[i] = {data.x[g], data.q[g]};
      c.inverse_inertia[i] = world_inverse_inertia(model.defs[g], data.q[g]);
    }
    c.rows.clear();
    c.row_begin.assign(1, 0);
    c.frames.resize(c.joints.size());
    for (std::size_t k = 0; k < c.joints.size(); ++k) {
      const JointDef& def = model.joints[c.joints[k]];
      c.frames[k] = joint_frames(def, pose(def.body0, false), pose(def.body1, false));
      const int side[2] = {def.body0 == kWorldBody ? -1 : js.local[def.body0],
                           def.body1 == kWorldBody ? -1 : js.local[def.body1]};
      const std::size_t first = c.rows.size();
      append_joint_rows(def, c.joints[k], c.frames[k], joint_coordinates(c.frames[k]), side, c.rows);
      for (std::size_t r = first; r < c.rows.size(); ++r) {
        c.rows[r].joint = static_cast<int>(k);  // (its position in the component)
        if (c.rows[r].kind != RowKind::kDrive) continue;
        const int dof = c.rows[r].coordinate == RowCoordinate::kTrans ? kTransX + c.rows[r].axis : kRotX + c.rows[r].axis;
        set_drive_compliance(def.drives[dof], coupling(c.rows[r], c.rows[r]), h, c.rows[r]);
      }
      c.row_begin.push_back(static_cast<int>(c.rows.size()));
    }
    c.drives = std::any_of(c.rows.begin(), c.rows.end(), [](const JointRow& row) { return row.kind == RowKind::kDrive; });
    c.needed.resize(c.joints.size());
    for (std::size_t k = 0; k < c.joints.size(); ++k) {
      c.needed[k] = needed_coordinates(c.rows.data() + c.row_begin[k], c.row_begin[k + 1] - c.row_begin[k]);
    }
    analyze_pattern();
  }

  // The system's pattern, when the component's joints or their rows changed: a node per
  // joint, a block per pair of joints on one body
  void analyze_pattern() {
    const int nj = static_cast<int>(c.joints.size());
    std::vector<int> sizes(nj);
    for (int k = 0; k < nj; ++k) sizes[k] = c.row_begin[k + 1] - c.row_begin[k];
    if (c.pattern_joints == c.joints && c.pattern_rows == sizes) return;
    c.pattern_joints = c.joints;
    c.pattern_rows = sizes;
    const int nb = static_cast<int>(c.bodies.size());
    c.joints_at.assign(nb, {});
    for (int k = 0; k < nj; ++k) {
      const JointDef& def = model.joints[c.joints[k]];
      for (int g : {def.body0, def.body1}) {
        if (g != kWorldBody && js.local[g] >= 0) c.joints_at[js.local[g]].push_back(k);
      }
    }
    std::vector<std::pair<int, int>> adjacent;
    for (const std::vector<int>& at : c.joints_at) {
      for (std::size_t a = 0; a < at.size(); ++a) {
        for (std::size_t b = a + 1; b < at.size(); ++b) adjacent.push_back({at[a], at[b]});
      }
    }
    c.system.analyze(sizes, adjacent);
    // a loop: more joints than a tree of the bodies and the immovable ones (the world and
    // kinematic bodies, counted as one) would have
    bool immovable = false;
    for (int k = 0; k < nj; ++k) {
      const JointDef& def = model.joints[c.joints[k]];
      immovable = immovable || !dynamic_body(model, def.body0) || !dynamic_body(model, def.body1);
    }
    c.loops = nj > nb - 1 + (immovable ? 1 : 0);
    c.regularization = c.loops ? kLoopRegularization : kTreeRegularization;
    c.block_at.assign(nb, {});
    const double* base = c.system.data();
    for (int i = 0; i < nb; ++i) {
      for (int a : c.joints_at[i]) {
        for (int b : c.joints_at[i]) c.block_at[i].push_back(static_cast<int>(c.system.block(a, b) - base));
      }
    }
  }

  // The component's velocities and row impulses kept, and brought back
  void save() {
    c.saved_v.resize(c.bodies.size());
    c.saved_l.resize(c.bodies.size());
    c.saved_impulse.resize(c.rows.size());
    for (std::size_t i = 0; i < c.bodies.size(); ++i) {
      c.saved_v[i] = data.v[c.bodies[i]];
      c.saved_l[i] = data.l[c.bodies[i]];
    }
    for (std::size_t r = 0; r < c.rows.size(); ++r) c.saved_impulse[r] = c.rows[r].impulse;
  }
  void restore() {
    for (std::size_t i = 0; i < c.bodies.size(); ++i) {
      data.v[c.bodies[i]] = c.saved_v[i];
      data.l[c.bodies[i]] = c.saved_l[i];
    }
    for (std::size_t r = 0; r < c.rows.size(); ++r) c.rows[r].impulse = c.saved_impulse[r];
    mark_clamped();
  }

  // A drive row is out of the solve exactly while its impulse is at its bound (after a
  // restore or a retake its impulse may be below it again: it rejoins the solve)
  void mark_clamped() {
    for (JointRow& row : c.rows) {
      if (row.kind == RowKind::kDrive) row.clamped = std::abs(row.impulse) >= row.max_impulse;
    }
  }

  // The last Newton step again, scaled by alpha, from the iterate it was taken at
  void retake(double alpha) {
    for (std::size_t r = 0; r < c.rows.size(); ++r) {
      if (c.step[r] != 0.0) apply(c.rows[r], alpha * c.step[r]);
    }
    mark_clamped();
  }

  void predict() {
    for (std::size_t i = 0; i < c.bodies.size(); ++i) {
      const int g = c.bodies[i];
      c.candidate[i] = {data.x[g] + h * data.v[g], free_rotation(model.defs[g], data.q[g], data.l[g], h)};
    }
  }

  // Which rows take part in this iteration, and what each asks; the largest error left
  double gather(bool first) {
    std::vector<JointCoordinates>& at = c.coordinates;
    at.resize(c.joints.size());
    c.end_frames.resize(c.joints.size());
    for (std::size_t k = 0; k < c.joints.size(); ++k) {
      const JointDef& def = model.joints[c.joints[k]];
      c.end_frames[k] = joint_frames(def, pose(def.body0, true), pose(def.body1, true));
      at[k] = joint_coordinates(c.end_frames[k], c.needed[k]);
    }
    if (first) {
      for (JointRow& row : c.rows) {
        if (row.coordinate == RowCoordinate::kCone) aim_cone_row(model.joints[c.joints[row.joint]], c.frames[row.joint], at[row.joint], row);
      }
      c.measured = c.rows;
    }
    c.in_solve.assign(c.rows.size(), 0);
    c.residual.assign(c.rows.size(), 0.0);
    double worst = 0.0;
    for (int r = 0; r < static_cast<int>(c.rows.size()); ++r) {
      JointRow& row = c.rows[r];
      // the rows' Jacobians where the bodies end the step: how the measured coordinates move
      // (a drive's and a cone's: at the start)
      if (row.kind != RowKind::kDrive) set_row_jacobian(c.end_frames[row.joint], at[row.joint], c.measured[r]);
      double wanted;
      if (row.kind == RowKind::kDrive) {
        if (row.clamped) continue;
        wanted = row.rate - rate(row) - row.compliance * row.impulse;
        worst = std::max(worst, h * std::abs(wanted));
      } else {
        const double e = measured_coordinate(row, at[row.joint]) - row.target;
        const bool held = row.kind == RowKind::kEquality || (row.kind == RowKind::kLower ? (e < 0.0 || row.impulse > 0.0)
                                                                                        : (e > 0.0 || row.impulse < 0.0));
        if (!held) continue;
        wanted = -e / h;
        worst = std::max(worst, std::abs(e));
      }
      c.in_solve[r] = 1;
      c.residual[r] = wanted;
    }
    return worst;
  }

  // A dlambda = residual over the rows in the solve, solved and applied within the rows' bounds
  void solve(bool first, bool refactor) {
    const int m = static_cast<int>(c.rows.size());
    c.step.assign(m, 0.0);
    if (std::find(c.in_solve.begin(), c.in_solve.end(), 1) == c.in_solve.end()) return;
    std::vector<double>& b = c.rhs;
    std::vector<double>& delta = c.delta;
    std::vector<char>& bounded = c.bounded;
    b = c.residual;
    bounded.assign(m, 0);
    // The last factorization again (a chord step), while it is of the same rows and no drive
    // of it was held at its bound: the Newton loop asks for a fresh one when the error stops
    // falling fast
    bool fresh = refactor || !c.factored || c.factored_rows != c.in_solve || c.factored_bounded;
    if (!fresh) {
      delta = b;
      c.system.solve(delta.data());
      for (int r = 0; r < m && !fresh; ++r) {
        if (!std::isfinite(delta[r])) fresh = true;
        if (c.in_solve[r] && c.rows[r].kind == RowKind::kDrive && std::abs(c.rows[r].impulse + delta[r]) > c.rows[r].max_impulse) fresh = true;
      }
    }
    if (fresh && !factor_and_solve(first)) return;
    for (int r = 0; r < m; ++r) {
      if (!c.in_solve[r]) continue;
      JointRow& row = c.rows[r];
      double total = row.impulse + delta[r];
      if (bounded[r]) {
        total = std::clamp(total, -row.max_impulse, row.max_impulse);
        row.clamped = true;
      }
      if (row.kind == RowKind::kLower) total = std::max(total, 0.0);
      if (row.kind == RowKind::kUpper) total = std::min(total, 0.0);
      c.step[r] = total - row.impulse;
      apply(row, total - row.impulse);
    }
  }

  // A assembled and factored, and solved; a drive that would pass its bound is held at it
  // (its row of A becomes the identity, its right-hand side the impulse that reaches the
  // bound) and the system solved again, so that the other rows' impulses are those for the
  // bounded drive, not the unbounded one (taking those gave a wheel glued to a bar half its
  // drive's torque, after the line search). False if it cannot be solved
  bool factor_and_solve(bool first) {
    const int m = static_cast<int>(c.rows.size());
    std::vector<double>& b = c.rhs;
    std::vector<double>& delta = c.delta;
    std::vector<char>& bounded = c.bounded;
    c.factored = false;
    assemble(first);
    for (int attempt = 0; attempt <= m; ++attempt) {
      if (attempt > 0) c.system.set_values(c.assembled);
      for (int r = 0; r < m; ++r) {
        if (!c.in_solve[r] || bounded[r]) set_unit_row(r);
      }
      if (!c.system.factorize()) return false;
      delta = b;
      c.system.solve(delta.data());
      for (double d : delta) {
        if (!std::isfinite(d)) return false;
      }
      bool more = false;
      for (int r = 0; r < m; ++r) {
        const JointRow& row = c.rows[r];
        if (!c.in_solve[r] || row.kind != RowKind::kDrive || bounded[r] || std::abs(row.impulse + delta[r]) <= row.max_impulse) continue;
        bounded[r] = 1;
        more = true;
        b[r] = std::clamp(row.impulse + delta[r], -row.max_impulse, row.max_impulse) - row.impulse;
      }
      if (!more) break;
    }
    c.factored = true;
    c.factored_rows = c.in_solve;
    c.factored_bounded = std::find(bounded.begin(), bounded.end(), 1) != bounded.end();
    return true;
  }

  // Row r of the system the identity's (a row out of the solve: its impulse stays)
  void set_unit_row(int r) {
    const int k = c.rows[r].joint;
    c.system.set_unit_row(k, r - c.row_begin[k]);
  }

  // A = J_end M^-1 J_start^T: how each row's coordinate at the end of the step moves with
  // each row's impulse (not symmetric once the bodies turn in the step; with a mass ratio
  // of 1000 the light bodies' turn matters even when it is small), M^-1's angular part the
  // candidate rotation's own response to L (free_rotation: a link turning a radian
  // in a step turns a third less per unit of L than I^-1 says), summed over the bodies
  // two rows share, with the drives' compliance and a little regularization on the diagonal.
  // The first iteration, which finds nearly all of the impulse, takes the symmetric J_start
  // M^-1 J_start^T: where joints close loops (a glued wall) the rows are redundant, and the
  // regularized symmetric system gives the impulses of least norm instead of arbitrary
  // self-cancelling ones, so that what each joint carries (its break test) is meaningful.
  // Rows out of the solve are left zero here (set_unit_row makes them the identity's)
  void assemble(bool first) {
    const int m = static_cast<int>(c.rows.size());
    c.system.set_zero();
    double* values = c.system.data();
    // how each candidate turns with L, over h (only a fresh factorization needs it)
    if (!first) {
      c.rotation_response.resize(c.bodies.size());
      for (std::size_t i = 0; i < c.bodies.size(); ++i) {
        c.rotation_response[i] = rotation_response(c.start[i].q, c.candidate[i].q, c.inverse_inertia[i]);
      }
    }
    // each row's M^-1 J^T on each of its sides
    c.response.resize(4 * m);
    for (int r = 0; r < m; ++r) {
      const JointRow& row = c.rows[r];
      for (int s = 0; s < 2; ++s) {
        if (row.side[s] < 0) continue;
        c.response[4 * r + 2 * s] = inverse_mass(row.side[s]) * row.linear[s];
        c.response[4 * r + 2 * s + 1] =
            (first ? c.inverse_inertia[row.side[s]] : c.rotation_response[row.side[s]]) * row.angular[s];
      }
    }
    for (int i = 0; i < static_cast<int>(c.bodies.size()); ++i) {
      const std::vector<int>& at = c.joints_at[i];
      const int na = static_cast<int>(at.size());
      for (int a = 0; a < na; ++a) {
        const int ka = at[a];
        for (int r = c.row_begin[ka]; r < c.row_begin[ka + 1]; ++r) {
          if (!c.in_solve[r]) continue;
          const JointRow& e = first ? c.rows[r] : c.measured[r];
          const int se = c.rows[r].side[0] == i ? 0 : 1;
          const Vec3& e_linear = e.linear[se];
          const Vec3& e_angular = e.angular[se];
          for (int b = 0; b < na; ++b) {
            const int kb = at[b];
            const int cols = c.row_begin[kb + 1] - c.row_begin[kb];
            double* out = values + c.block_at[i][a * na + b] + (r - c.row_begin[ka]) * cols;
            for (int s = c.row_begin[kb]; s < c.row_begin[kb + 1]; ++s) {
              const int ss = c.rows[s].side[0] == i ? 0 : 1;
              out[s - c.row_begin[kb]] +=
                  e_linear.dot(c.response[4 * s + 2 * ss]) + e_angular.dot(c.response[4 * s + 2 * ss + 1]);
            }
          }
        }
      }
    }
    for (int r = 0; r < m; ++r) {
      if (!c.in_solve[r]) continue;
      const JointRow& row = c.rows[r];
      const int k = row.joint;
      const int n = c.row_begin[k + 1] - c.row_begin[k];
      c.system.block(k, k)[(r - c.row_begin[k]) * (n + 1)] += coupling(row, row) * c.regularization + row.compliance;
    }
    // (kept for a second attempt, should a drive reach its bound)
    if (c.drives) c.assembled = c.system.values();
  }

  // The joint's force and torque on body 1 over the step (N, N m) from its rows' impulses
  void record_loads() {
    for (std::size_t k = 0; k < c.joints.size(); ++k) {
      data.joints.force[c.joints[k]] = Vec3::Zero();
      data.joints.torque[c.joints[k]] = Vec3::Zero();
    }
    for (const JointRow& row : c.rows) {
      const int j = c.joints[row.joint];
      const bool linear = row.coordinate == RowCoordinate::kTrans || row.coordinate == RowCoordinate::kDistance;
      const Vec3 direction = linear ? (row.side[1] >= 0 || row.side[0] < 0 ? Vec3(row.linear[1]) : Vec3(-row.linear[0]))
                                    : Vec3(row.angular[1]);
      (linear ? data.joints.force[j] : data.joints.torque[j]) += row.impulse / h * direction;
    }
  }
};

}  // namespace

void solve_joints(const RigidModel& model, RigidData& data, JointScratch& js, double dt, double end_time) {
  if (model.joints.empty()) return;
  find_components(model, data, js);
  tbb::parallel_for(0, js.count, [&](int k) {
    ComponentSolver solver{model, data, js, js.components[k], dt};
    solver.begin();
    // Newton iterations; the best iterate is kept (where the bodies turn too far in a step
    // for the linearization an iteration can make things worse: its step is then halved, a
    // line search on the impulses)
    double best = kUnlimited, alpha = 1.0, last = kUnlimited;
    solver.c.factored = false;
    for (int iteration = 0; iteration <= kIterations; ++iteration) {
      solver.predict();
      const double worst = solver.gather(iteration == 0);
      // (a chord step that took the error down by less than this asks for a fresh factorization)
      const bool refactor = !(worst < kChordRate * last);
      last = worst;
      if (worst < best) {
        best = worst;
        alpha = 1.0;
        solver.save();
      } else if (worst > kDivergence) {
        solver.restore();
        alpha *= 0.5;
        if (alpha < 1.0 / 64.0) break;
        solver.retake(alpha);
        continue;
      }
      if (worst <= kTolerance || iteration == kIterations) break;
      // (where joints close loops the first solve is the symmetric one: see assemble)
      solver.solve(iteration == 0 && solver.c.loops, refactor);
    }
    solver.restore();
    solver.record_loads();
    solver.c.error = best;
  });
  js.error = 0.0;
  for (int k = 0; k < js.count; ++k) js.error = std::max(js.error, js.components[k].error);
  // breaking, in joint order
  for (int k = 0; k < js.count; ++k) {
    for (int j : js.components[k].joints) {
      const JointDef& def = model.joints[j];
      if (data.joints.force[j].norm() > def.break_force || data.joints.torque[j].norm() > def.break_torque) {
        data.joints.enabled[j] = 0;
        data.joints.broke_at[j] = end_time;
      }
    }
  }
}

void project_joint_velocities(const RigidModel& model, RigidData& data, JointScratch& js, double dt) {
  if (model.joints.empty()) return;
  tbb::parallel_for(0, js.count, [&](int k) {
    JointComponent& c = js.components[k];
    // (a component with a body put to sleep, a joint broken or one to a moving kinematic
    // body since its solve is left as it is)
    for (int g : c.bodies) {
      if (data.asleep[g]) return;
    }
    for (int j : c.joints) {
      const JointDef& def = model.joints[j];
      if (!data.joints.enabled[j]) return;
      for (int g : {def.body0, def.body1}) {
        if (g != kWorldBody && moving_kinematic(model, data, g)) return;
      }
    }
    ComponentSolver solver{model, data, js, c, dt};
    solver.begin();
    const int m = static_cast<int>(c.rows.size());
    c.in_solve.assign(m, 0);
    c.residual.assign(m, 0.0);
    for (int r = 0; r < m; ++r) {
      if (c.rows[r].kind != RowKind::kEquality) continue;
      c.in_solve[r] = 1;
      c.residual[r] = -solver.rate(c.rows[r]);
    }
    solver.solve(/*first=*/true, /*refactor=*/true);
  });
}

JointError joint_error(const RigidModel& model, const RigidData& data, int j) {
  JointError error;
  if (!data.joints.enabled[j]) return error;
  const JointDef& def = model.joints[j];
  const auto pose = [&](int g) { return g == kWorldBody ? BodyPose{} : BodyPose{data.x[g], data.q[g]}; };
  const JointCoordinates c = joint_coordinates(joint_frames(def, pose(def.body0), pose(def.body1)));
  const auto outside = [](double value, double lower, double upper) {
    return std::max({0.0, lower - value, value - upper});
  };
  // the gap: off the locked and limited translations, or past the distance range
  if (def.distance) {
    error.gap = outside(c.distance, def.min_distance, def.max_distance);
  } else {
    Vec3 off = Vec3::Zero();
    for (int k = 0; k < 3; ++k) {
      const DofLimit& d = def.dofs[kTransX + k];
      if (d.motion == DofMotion::kLocked) off[k] = c.offset[k];
      if (d.motion == DofMotion::kLimited) off[k] = outside(c.offset[k], d.lower, d.upper);
    }
    error.gap = off.norm();
  }
  // the angle: off the locked rotations, past the limits and the cone
  int locked = 0;
  for (int k = 0; k < 3; ++k) locked += def.dofs[kRotX + k].motion == DofMotion::kLocked;
  if (locked == 3) {
    error.angle = c.rotation.norm();
  } else {
    if (locked == 2) error.angle = std::asin(std::min(1.0, c.alignment.norm()));
    const DofLimit& twist = def.dofs[kRotX];
    if (twist.motion == DofMotion::kLocked && locked != 2) error.angle = std::max(error.angle, std::abs(c.twist));
    if (twist.motion == DofMotion::kLimited) error.angle = std::max(error.angle, outside(c.twist, twist.lower, twist.upper));
    if (def.cone) error.angle = std::max(error.angle, c.swing.norm() - std::min(c.swing.norm(), cone_limit(def, c.swing)));
  }
  return error;
}

}  // namespace simbake
