// Self-collision's continuous collisions (the second of the three parts at the top of
// self_collision.h): the times in the step at which a candidate's four points are coplanar,
// the roots of a cubic, and an inelastic impulse at the earliest of them that is a contact.
#include "cloth/self_collision.h"

#include "cloth/self_collision_detail.h"
#include "geometry/closest_points.h"

#include <atomic>
#include <cmath>

namespace simbake {

using namespace self_collision_detail;

namespace {

// Roots in [0, 1] of a t^3 + b t^2 + c t + d, ascending: [0, 1] is cut at the roots of the
// derivative, and each piece whose ends differ in sign (or touch zero) is bisected
int cubic_roots(double a, double b, double c, double d, double roots[3]) {
  // no root in [0, 1] when the Bernstein coefficients share one sign (the curve lies in
  // their convex hull)
  const double b0 = d, b1 = d + c / 3, b2 = d + (2 * c + b) / 3, b3 = a + b + c + d;
  if ((b0 > 0 && b1 > 0 && b2 > 0 && b3 > 0) || (b0 < 0 && b1 < 0 && b2 < 0 && b3 < 0)) return 0;
  const double scale = std::max({std::abs(a), std::abs(b), std::abs(c), std::abs(d)});
  if (scale == 0.0) return 0;  // coplanar throughout: left to the proximity test
  a /= scale, b /= scale, c /= scale, d /= scale;
  const auto f = [&](double t) { return ((a * t + b) * t + c) * t + d; };
  double cuts[4] = {0.0, 0.0, 0.0, 1.0};
  int ncuts = 1;
  // critical points: 3a t^2 + 2b t + c = 0
  const double qa = 3 * a, qb = 2 * b, qc = c;
  double crit[2];
  int ncrit = 0;
  if (std::abs(qa) > 1e-14) {
    const double disc = qb * qb - 4 * qa * qc;
    if (disc >= 0.0) {
      const double s = std::sqrt(disc);
      const double q = -0.5 * (qb + (qb >= 0 ? s : -s));
      crit[ncrit++] = q / qa;
      if (q != 0.0) crit[ncrit++] = qc / q;
    }
  } else if (std::abs(qb) > 1e-14) {
    crit[ncrit++] = -qc / qb;
  }
  std::sort(crit, crit + ncrit);
  for (int k = 0; k < ncrit; ++k) {
    if (crit[k] > 0.0 && crit[k] < 1.0) cuts[ncuts++] = crit[k];
  }
  cuts[ncuts++] = 1.0;
  int count = 0;
  double flo = f(cuts[0]);
  if (flo == 0.0) roots[count++] = 0.0;
  for (int k = 0; k + 1 < ncuts; ++k) {
    double lo = cuts[k], hi = cuts[k + 1];
    double fl = f(lo), fh = f(hi);
    if (fh == 0.0) {
      if (count == 0 || roots[count - 1] < hi) roots[count++] = hi;
      continue;
    }
    if ((fl < 0.0) == (fh < 0.0) || fl == 0.0) continue;
    for (int it = 0; it < 60 && hi - lo > 1e-13; ++it) {
      const double mid = 0.5 * (lo + hi), fm = f(mid);
      if ((fm < 0.0) == (fl < 0.0)) {
        lo = mid;
        fl = fm;
      } else {
        hi = mid;
      }
    }
    roots[count++] = 0.5 * (lo + hi);
    if (count == 3) break;
  }
  return count;
}

// the cubic in s whose roots are the times at which x0 + s v0, ..., x3 + s v3 are coplanar:
// ((x1 - x0) x (x2 - x0)) . (x3 - x0)
void coplanarity_cubic(const Vec3 x[4], const Vec3 d[4], double coef[4]) {
  const Vec3 x1 = x[1] - x[0], x2 = x[2] - x[0], x3 = x[3] - x[0];
  const Vec3 v1 = d[1] - d[0], v2 = d[2] - d[0], v3 = d[3] - d[0];
  const Vec3 A = x1.cross(x2), B = x1.cross(v2) + v1.cross(x2), C = v1.cross(v2);
  coef[0] = C.dot(v3);
  coef[1] = B.dot(v3) + C.dot(x3);
  coef[2] = A.dot(v3) + B.dot(x3);
  coef[3] = A.dot(x3);
}

}  // namespace

// The earliest contact of one candidate over the step into `found`, if any; the pair marked
// clear otherwise. True when it took the continuous test (its distance minus its relative
// motion was within the tolerance)
bool SelfCollision::earliest_contact(int kind, Pair& pair, const Points& x, const Points& v, double dt,
                                     double tolerance, std::vector<Contact>& found) const {
  const Passes& m = passes_;
  // a pair whose distance minus its relative motion is above this cannot collide (the slack
  // covers round-off in the distances)
  const double reach_limit = tolerance * (1.0 + 1e-6) + 1e-12;
  const std::array<int, 4>& ids = pair.vertex;
  if (pair.clear >= m.first && m.changed[ids[0]] <= pair.clear && m.changed[ids[1]] <= pair.clear &&
      m.changed[ids[2]] <= pair.clear && m.changed[ids[3]] <= pair.clear) {
    return false;  // clear at a pass since which none of its vertices' velocities changed
  }
  pair.clear = m.pass;
  Vec3 d[4];
  for (int k = 0; k < 4; ++k) d[k] = dt * row(v, ids[k]);
  // d - R: the distance minus the pair's relative motion R, a lower bound of its distance
  // over the step (the exact distance taken where the boxes' gap is not enough)
  const double r = kind == 0
      ? std::sqrt(std::max({(d[1] - d[0]).squaredNorm(), (d[2] - d[0]).squaredNorm(), (d[3] - d[0]).squaredNorm()}))
      : (d[1] - d[0]).norm() + std::sqrt(std::max((d[2] - d[0]).squaredNorm(), (d[3] - d[0]).squaredNorm()));
  if (pair.distance - reach_limit > r) return false;
  if (!pair.exact) {
    Contact c;
    pair.distance = pair_contact(kind, ids, x, 0.0, c);
    pair.exact = true;
    if (pair.distance - reach_limit > r) return false;
  }
  Vec3 p[4];
  for (int k = 0; k < 4; ++k) p[k] = row(x, ids[k]);
  // the two sides' boxes over the step
  const int split = kind == 0 ? 1 : 2;
  Box3 first, second;
  for (int k = 0; k < 4; ++k) {
    Box3& box = k < split ? first : second;
    box.extend(p[k]);
    box.extend(p[k] + d[k]);
  }
  first.min().array() -= tolerance;
  first.max().array() += tolerance;
  if (!first.intersects(second)) return true;
  // coplanarity: point and triangle (p0; p1 p2 p3) or the two edges (p0 p1; p2 p3)
  double coef[4], roots[4];
  const Vec3 order[4] = {p[1], p[2], p[3], p[0]};
  const Vec3 motion[4] = {d[1], d[2], d[3], d[0]};
  coplanarity_cubic(order, motion, coef);
  int count = cubic_roots(coef[0], coef[1], coef[2], coef[3], roots);
  // and the end of the step: a pair that ends closer than the tolerance collides too (a
  // pair ending exactly in one plane, as two layers both pressed to a surface at the
  // thickness do, has its root at 1 lost to round-off)
  if (count == 0 || roots[count - 1] < 1.0) roots[count++] = 1.0;
  for (int r = 0; r < count; ++r) {
    const double s = roots[r];
    Vec3 q[4];
    for (int k = 0; k < 4; ++k) q[k] = p[k] + s * d[k];
    Contact c;
    Vec3 normal;
    double distance;
    if (kind == 0) {
      const Vec3 w = closest_on_triangle(q[0], q[1], q[2], q[3]);
      distance = (q[0] - (w[0] * q[1] + w[1] * q[2] + w[2] * q[3])).norm();
      c = Contact{{ids[0], ids[1], ids[2], ids[3]}, {1.0, -w[0], -w[1], -w[2]}, Vec3::Zero(), 0.0};
      normal = (q[2] - q[1]).cross(q[3] - q[1]);
    } else {
      const auto [a, b] = closest_on_segments(q[0], q[1], q[2], q[3]);
      distance = ((q[0] + a * (q[1] - q[0])) - (q[2] + b * (q[3] - q[2]))).norm();
      c = Contact{{ids[0], ids[1], ids[2], ids[3]}, {1.0 - a, a, -(1.0 - b), -b}, Vec3::Zero(), 0.0};
      normal = (q[1] - q[0]).cross(q[3] - q[2]);
      if (normal.squaredNorm() < 1e-24 * (q[1] - q[0]).squaredNorm() * (q[3] - q[2]).squaredNorm()) {
        // parallel edges: the direction between them at the start of the step
        const auto [a0, b0] = closest_on_segments(p[0], p[1], p[2], p[3]);
        normal = (p[0] + a0 * (p[1] - p[0])) - (p[2] + b0 * (p[3] - p[2]));
      }
    }
    if (distance > tolerance || normal.squaredNorm() == 0.0) continue;
    normal.normalize();
    // the normal points the way the first side must go to stay where it was: against the
    // relative motion; a pair with no closing motion along it (in touch and moving together,
    // as a rigid impact zone does) does not collide
    Vec3 relative = Vec3::Zero();
    for (int k = 0; k < 4; ++k) relative += c.weight[k] * d[k];
    if (relative.dot(normal) > 0.0) normal = -normal;
    if (!(relative.dot(normal) < 0.0)) continue;
    c.normal = normal;
    c.time = s;
    found.push_back(c);
    pair.clear = -1;
    return true;  // the earliest contact of the pair
  }
  return true;
}

void SelfCollision::collision_contacts(const Points& x, const Points& v, double dt,
                                       const SelfCollisionSettings& settings, std::vector<Contact>& out,
                                       SelfCollisionStatistics& stats) {
  out.clear();
  if (over_budget_) return;
  start(x, v, dt, settings, stats);
  if (over_budget_) return;
  // the pass budget: the pairs this pass visits, with the step's earlier passes'
  long long visits = 0;
  for (int list = 0; list < 4; ++list) visits += static_cast<long long>(pair_list(list).size());
  const double pass_limit = settings.pass_budget * std::max(vertex_count_, settings.budget_vertices);
  if (static_cast<double>(pass_work_ + visits) > pass_limit) {
    stop_over_budget(stats);
    return;
  }
  pass_work_ += visits;
  stats.pass_peak = std::max(stats.pass_peak, pass_work_);
  const double tolerance = collision_tolerance(settings);
  // this pass, and the vertices whose velocities changed since the last
  Passes& m = passes_;
  ++m.pass;
  if (m.changed.size() != static_cast<size_t>(vertex_count_) || m.dt != dt || m.tolerance != tolerance) {
    m.first = m.pass;
    m.changed.assign(vertex_count_, m.pass);
    m.velocity = v;
    m.dt = dt;
    m.tolerance = tolerance;
  }
  for (int k = 0; k < vertex_count_; ++k) {
    if (v.row(k) != m.velocity.row(k)) {
      m.changed[k] = m.pass;
      m.velocity.row(k) = v.row(k);
    }
  }
  std::atomic<long long> tests{0};
  // an obstacle against a cloth item with a vertex it has let in (settings.yielding): not kept apart
  const std::vector<char>* yielding = settings.yielding;
  const auto let_through = [&](const std::array<int, 4>& ids) {
    bool obstacle_side = false, let_in = false;
    for (int k = 0; k < 4; ++k) {
      obstacle_side = obstacle_side || obstacle(ids[k]);
      let_in = let_in || (!obstacle(ids[k]) && (*yielding)[ids[k]]);
    }
    return obstacle_side && let_in;
  };
  for (int list = 0; list < 4; ++list) {
    const int kind = list % 2;
    std::vector<Pair>& pairs = pair_list(list);
    parallel_collect(pairs.size(), out, [&](size_t n, std::vector<Contact>& found) {
      if (yielding && let_through(pairs[n].vertex)) return;
      if (earliest_contact(kind, pairs[n], x, v, dt, tolerance, found)) tests.fetch_add(1, std::memory_order_relaxed);
    });
  }
  // earliest first (the order does not depend on how the pairs were found)
  std::sort(out.begin(), out.end(), [](const Contact& a, const Contact& b) {
    return a.time != b.time ? a.time < b.time : std::lexicographical_compare(a.vertex, a.vertex + 4, b.vertex, b.vertex + 4);
  });
  stats.tests += tests.load();
}

bool SelfCollision::collide(const Points& x, Points& v, const Eigen::VectorXd& inverse_mass, double dt,
                            const SelfCollisionSettings& settings, SelfCollisionStatistics& stats, int passes) {
  const double separation = kSeparation * settings.thickness / dt;
  std::vector<Contact> contacts;
  for (int pass = 0; pass < passes; ++pass) {
    collision_contacts(x, v, dt, settings, contacts, stats);
    if (over_budget_) return false;
    if (contacts.empty()) return true;
    for (const Contact& c : contacts) {
      stats.collisions += apply_impulse(c, separation, settings.friction, v, inverse_mass, settings.support);
    }
  }
  return false;
}

}  // namespace simbake
