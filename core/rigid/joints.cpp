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

#include <Eigen/SparseLU>
#include <Eigen/SparseCore>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

namespace simbake {

namespace {

constexpr int kIterations = 16;         // Newton iterations per step, at most
constexpr double kTolerance = 1e-10;    // (m, rad) error at which a step's solve stops early
constexpr double kDivergence = 1e-6;    // (m, rad) an error this small never counts as diverging
constexpr double kRegularization = 1e-5;  // relative to A's diagonal: redundant rows stay solvable

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
    c.body_rows.resize(nb);
    for (int i = 0; i < nb; ++i) {
      const int g = c.bodies[i];
      c.start[i] = {data.x[g], data.q[g]};
      c.inverse_inertia[i] = world_inverse_inertia(model.defs[g], data.q[g]);
    }
    c.rows.clear();
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
    std::vector<JointCoordinates> at(c.joints.size());
    c.measured.clear();
    for (std::size_t k = 0; k < c.joints.size(); ++k) {
      const JointDef& def = model.joints[c.joints[k]];
      const JointFrames frames = joint_frames(def, pose(def.body0, true), pose(def.body1, true));
      at[k] = joint_coordinates(frames);
      // (the rows' Jacobians where the bodies end the step: how the measured coordinates move)
      const int side[2] = {-1, -1};
      append_joint_rows(def, static_cast<int>(k), frames, at[k], side, c.measured);
    }
    c.active.clear();
    c.residual.clear();
    double worst = 0.0;
    for (int r = 0; r < static_cast<int>(c.rows.size()); ++r) {
      JointRow& row = c.rows[r];
      if (first && row.coordinate == RowCoordinate::kCone) {
        aim_cone_row(model.joints[c.joints[row.joint]], c.frames[row.joint], at[row.joint], row);
      }
      JointRow& moved = c.measured[r];
      if (row.kind == RowKind::kDrive || row.coordinate == RowCoordinate::kCone) {  // (J at the start)
        moved.linear[0] = row.linear[0];
        moved.linear[1] = row.linear[1];
        moved.angular[0] = row.angular[0];
        moved.angular[1] = row.angular[1];
      }
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
      c.active.push_back(r);
      c.residual.push_back(wanted);
    }
    return worst;
  }

  // The LU of A: its pattern analysed again only when it differs from the last one's (the
  // ordering depends on the pattern alone, so the factors are the same bits either way)
  Eigen::SparseLU<Eigen::SparseMatrix<double>, Eigen::COLAMDOrdering<int>>& factor(const Eigen::SparseMatrix<double>& A) {
    const int* outer = A.outerIndexPtr();
    const int* inner = A.innerIndexPtr();
    const bool same = c.lu && static_cast<Eigen::Index>(c.pattern_outer.size()) == A.outerSize() + 1 &&
                      static_cast<Eigen::Index>(c.pattern_inner.size()) == A.nonZeros() &&
                      std::equal(c.pattern_outer.begin(), c.pattern_outer.end(), outer) &&
                      std::equal(c.pattern_inner.begin(), c.pattern_inner.end(), inner);
    if (!same) {
      if (!c.lu) c.lu = std::make_unique<Eigen::SparseLU<Eigen::SparseMatrix<double>, Eigen::COLAMDOrdering<int>>>();
      c.lu->analyzePattern(A);
      c.pattern_outer.assign(outer, outer + A.outerSize() + 1);
      c.pattern_inner.assign(inner, inner + A.nonZeros());
    }
    c.lu->factorize(A);
    return *c.lu;
  }

  // A dlambda = residual over the active rows, solved and applied within the rows' bounds
  void solve(bool first) {
    const int m = static_cast<int>(c.active.size());
    c.step.assign(c.rows.size(), 0.0);
    if (m == 0) return;
    std::vector<int> slot(c.rows.size(), -1);
    for (auto& list : c.body_rows) list.clear();
    for (int k = 0; k < m; ++k) {
      slot[c.active[k]] = k;
      for (int side : c.rows[c.active[k]].side) {
        if (side >= 0) c.body_rows[side].push_back(c.active[k]);
      }
    }
    // A = J_end M^-1 J_start^T: how each row's coordinate at the end of the step moves with
    // each row's impulse (not symmetric once the bodies turn in the step; with a mass ratio
    // of 1000 the light bodies' turn matters even when it is small), summed over the bodies
    // two rows share, with the drives' compliance and a little regularization on the diagonal.
    // The first iteration, which finds nearly all of the impulse, takes the symmetric J_start
    // M^-1 J_start^T: where joints close loops (a glued wall) the rows are redundant, and the
    // regularized symmetric system gives the impulses of least norm instead of arbitrary
    // self-cancelling ones, so that what each joint carries (its break test) is meaningful
    std::vector<Eigen::Triplet<double>> entries;
    for (int k = 0; k < m; ++k) {
      const JointRow& row = c.rows[c.active[k]];
      entries.emplace_back(k, k, coupling(row, row) * kRegularization + row.compliance);
    }
    for (int i = 0; i < static_cast<int>(c.body_rows.size()); ++i) {
      for (int r : c.body_rows[i]) {
        JointRow moved = first ? c.rows[r] : c.measured[r];
        moved.side[0] = c.rows[r].side[0];
        moved.side[1] = c.rows[r].side[1];
        for (int s : c.body_rows[i]) entries.emplace_back(slot[r], slot[s], coupling_at(moved, c.rows[s], i));
      }
    }
    // A drive that would pass its bound is held at it (its row of A becomes the identity, its
    // right-hand side the impulse that reaches the bound) and the system solved again, so that
    // the other rows' impulses are those for the bounded drive, not the unbounded one (taking
    // those gave a wheel glued to a bar half its drive's torque, after the line search)
    Eigen::VectorXd b = Eigen::Map<const Eigen::VectorXd>(c.residual.data(), m);
    std::vector<char> bounded(m, 0);
    Eigen::VectorXd delta;
    for (int attempt = 0; attempt <= m; ++attempt) {
      Eigen::SparseMatrix<double> A(m, m);
      A.setFromTriplets(entries.begin(), entries.end());
      A.makeCompressed();
      auto& lu = factor(A);
      if (lu.info() != Eigen::Success) return;
      delta = lu.solve(b);
      if (!delta.allFinite()) return;
      bool more = false;
      for (int k = 0; k < m; ++k) {
        const JointRow& row = c.rows[c.active[k]];
        if (row.kind != RowKind::kDrive || bounded[k] || std::abs(row.impulse + delta[k]) <= row.max_impulse) continue;
        bounded[k] = 1;
        more = true;
        b[k] = std::clamp(row.impulse + delta[k], -row.max_impulse, row.max_impulse) - row.impulse;
      }
      if (!more) break;
      std::vector<Eigen::Triplet<double>> kept;
      for (const auto& t : entries) {
        if (!bounded[t.row()]) kept.push_back(t);
      }
      for (int k = 0; k < m; ++k) {
        if (bounded[k]) kept.emplace_back(k, k, 1.0);
      }
      entries.swap(kept);
    }
    for (int k = 0; k < m; ++k) {
      JointRow& row = c.rows[c.active[k]];
      double total = row.impulse + delta[k];
      if (bounded[k]) {
        total = std::clamp(total, -row.max_impulse, row.max_impulse);
        row.clamped = true;
      }
      if (row.kind == RowKind::kLower) total = std::max(total, 0.0);
      if (row.kind == RowKind::kUpper) total = std::min(total, 0.0);
      c.step[c.active[k]] = total - row.impulse;
      apply(row, total - row.impulse);
    }
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
    // for the linearization an iteration can make things worse)
    // for the linearization an iteration can make things worse: its step is then halved, a
    // line search on the impulses)
    double best = kUnlimited, alpha = 1.0;
    for (int iteration = 0; iteration <= kIterations; ++iteration) {
      solver.predict();
      const double worst = solver.gather(iteration == 0);
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
      if ((worst <= kTolerance && iteration > 0) || iteration == kIterations) break;
      solver.solve(iteration == 0);
    }
    solver.restore();
    solver.record_loads();
  });
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
