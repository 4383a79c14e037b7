#include "cloth/self_collision.h"

#include "geometry/closest_points.h"
#include "geometry/mesh.h"

#include <Eigen/Dense>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>

namespace simbake {

namespace {

constexpr double kRepulsionRate = 0.1;      // a pair closer than h separates by 0.1 (h - d) per step at most
constexpr double kCollisionTolerance = 1e-2; // of h: coplanar pairs this close count as colliding
constexpr double kSeparation = 1e-3;        // of h per step: the separating speed a collision impulse leaves
constexpr double kMaxHeldAmplification = 4.0;  // see apply_impulse
constexpr double kMargin = 0.1;             // of the mean edge: how far a vertex's box reaches past
                                            // its start and end of the step
constexpr size_t kMovedFraction = 8;       // all pairs are found again when more than 1 / 8 of the vertices
                                            // leave their boxes at once
constexpr size_t kChunk = 512;              // pairs per parallel task (fixed: same result at any thread count)
constexpr double kFlat = 0.1;               // a pivot's triangles are flat when their normals stay within
                                            // acos(0.1) = 84 degrees of one direction (any angle under 90
                                            // would do; the rest is room for round-off)

Vec3 row(const Points& p, int k) { return p.row(k).transpose(); }

// how close coplanar pairs count as colliding (m)
double collision_tolerance(const SelfCollisionSettings& settings) {
  return std::max(kCollisionTolerance * settings.thickness, 1e-9);
}

// Closest point of triangle abc to p, as barycentric weights (u, v, w) of a, b, c
// (Ericson, Real-Time Collision Detection, 5.1.5)
Vec3 closest_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0.0 && d2 <= 0.0) return Vec3(1, 0, 0);
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) return Vec3(0, 1, 0);
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) {
    const double v = d1 / (d1 - d3);
    return Vec3(1 - v, v, 0);
  }
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) return Vec3(0, 0, 1);
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) {
    const double w = d2 / (d2 - d6);
    return Vec3(1 - w, 0, w);
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return Vec3(0, 1 - w, w);
  }
  const double denom = 1.0 / (va + vb + vc);
  const double v = vb * denom, w = vc * denom;
  return Vec3(1 - v - w, v, w);
}

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

// Applies an impulse along the contact's normal that brings the pair's relative normal
// velocity up to `target` (never down), with Coulomb friction on the relative slip limited
// by the same change; returns whether it did anything. With `support` (see
// SelfCollisionSettings::support), a vertex resting on a still surface (the normal of the
// surfaces it rests on this step, or zero) that the impulse would push into that surface
// takes none of it, as a pinned vertex: the surface holds it, and the pair's other vertices
// take the change
bool apply_impulse(const SelfCollision::Contact& c, double target, double friction, Points& v,
                   const Eigen::VectorXd& inverse_mass, const std::vector<Vec3>* support) {
  Vec3 relative = Vec3::Zero();
  for (int k = 0; k < 4; ++k) relative += c.weight[k] * row(v, c.vertex[k]);
  const double vn = relative.dot(c.normal);
  const double change = target - vn;
  if (!(change > 0.0)) return false;
  // each vertex's share of the change moves it along weight x normal: into its support if
  // that points against the support's normal
  double mass[4], denom = 0.0;
  bool held = false;
  for (int k = 0; k < 4; ++k) {
    const int i = c.vertex[k];
    mass[k] = inverse_mass[i];
    if (support && c.weight[k] * c.normal.dot((*support)[i]) < 0.0 && mass[k] > 0.0) {
      mass[k] = 0.0;
      held = true;
    }
    denom += c.weight[k] * c.weight[k] * mass[k];
  }
  if (denom <= 0.0) return false;
  // vertex k's velocity changes by |w_k| m_k / denom times the wanted change: with the held
  // vertices out, a pair left with one free vertex of small weight (a triangle's far corner)
  // would fling it (1 / w_k; on the ploughed sheet one repulsion put a vertex at 94 m/s and
  // the next steps at 1.7e5). Such a pair is left as one whose vertices are all held: to
  // the next passes and the impact zones
  if (held) {
    for (int k = 0; k < 4; ++k) {
      if (std::abs(c.weight[k]) * mass[k] > kMaxHeldAmplification * denom) return false;
    }
  }
  Vec3 delta = change * c.normal;  // the wanted change of the relative velocity
  const Vec3 slip = relative - vn * c.normal;
  const double slip_speed = slip.norm();
  if (slip_speed > 0.0) delta -= std::min(1.0, friction * change / slip_speed) * slip;
  for (int k = 0; k < 4; ++k) {
    const int i = c.vertex[k];
    v.row(i) += (c.weight[k] * mass[k] / denom) * delta.transpose();
  }
  return true;
}

}  // namespace

namespace {

// for_each(i, out) for i in [0, count), in parallel over fixed chunks; the outputs joined in
// order of i, so the result is the same at any thread count
template <class T, class ForEach>
void parallel_collect(size_t count, std::vector<T>& out, ForEach&& for_each) {
  const size_t chunks = (count + kChunk - 1) / kChunk;
  std::vector<std::vector<T>> found(chunks);
  tbb::parallel_for(size_t(0), chunks, [&](size_t chunk) {
    const size_t end = std::min(count, (chunk + 1) * kChunk);
    for (size_t i = chunk * kChunk; i < end; ++i) for_each(i, found[chunk]);
  });
  for (const auto& list : found) out.insert(out.end(), list.begin(), list.end());
}

}  // namespace

namespace {

// CSR lists of each vertex's items (items[i] holds count vertices): those of vertex k are
// items_of[first[k]], ..., items_of[first[k + 1] - 1], ascending
template <class Items>
void vertex_items(const Items& items, int item_count, int count, int vertex_count, std::vector<int>& first,
                  std::vector<int>& items_of) {
  first.assign(vertex_count + 1, 0);
  for (int i = 0; i < item_count; ++i)
    for (int k = 0; k < count; ++k) ++first[items(i, k) + 1];
  for (int k = 0; k < vertex_count; ++k) first[k + 1] += first[k];
  items_of.resize(first[vertex_count]);
  std::vector<int> next(first.begin(), first.end() - 1);
  for (int i = 0; i < item_count; ++i)
    for (int k = 0; k < count; ++k) items_of[next[items(i, k)]++] = i;
}

}  // namespace

namespace {

// the cloth's triangles, then each obstacle's, its vertices numbered after the cloth's and
// the obstacles' before it
Triangles joined_triangles(const Triangles& cloth, int cloth_vertices, const std::vector<TriangleMesh>& obstacles) {
  Eigen::Index rows = cloth.rows();
  for (const TriangleMesh& o : obstacles) rows += o.triangles.rows();
  Triangles all(rows, 3);
  all.topRows(cloth.rows()) = cloth;
  Eigen::Index row = cloth.rows();
  int offset = cloth_vertices;
  for (const TriangleMesh& o : obstacles) {
    all.middleRows(row, o.triangles.rows()) = o.triangles.array() + offset;
    row += o.triangles.rows();
    offset += static_cast<int>(o.vertices.rows());
  }
  return all;
}

}  // namespace

SelfCollision::SelfCollision(const Triangles& triangles, int vertex_count, const std::vector<TriangleMesh>& obstacles)
    : triangles_(joined_triangles(triangles, vertex_count, obstacles)),
      edges_(unique_edges(triangles_)),
      vertex_count_(vertex_count),
      cloth_vertices_(vertex_count) {
  cloth_triangles_ = static_cast<int>(triangles.rows());
  for (size_t o = 0; o < obstacles.size(); ++o) {
    vertex_count_ += static_cast<int>(obstacles[o].vertices.rows());
    obstacle_of_.resize(vertex_count_ - cloth_vertices_, static_cast<int>(o));
  }
  vertex_items([&](int t, int k) { return triangles_(t, k); }, static_cast<int>(triangles_.rows()), 3, vertex_count_,
               triangle_first_, vertex_triangles_);
  vertex_items([&](int e, int k) { return edges_[e][k]; }, static_cast<int>(edges_.size()), 2, vertex_count_,
               edge_first_, vertex_edges_);
  build_near();
}

SelfCollision::~SelfCollision() = default;
SelfCollision::SelfCollision(SelfCollision&&) noexcept = default;
SelfCollision& SelfCollision::operator=(SelfCollision&&) noexcept = default;

namespace {

// A pair's distance at x (kind 0: point ids[0] and triangle ids[1..3]; kind 1: edges ids[0..1]
// and ids[2..3]) as a contact: the weights of the closest points, the normal from the second
// side towards the first (across both sides where they touch, closer than `touch`)
double pair_contact(int kind, const std::array<int, 4>& ids, const Points& x, double touch,
                    SelfCollision::Contact& c) {
  const Vec3 p0 = row(x, ids[0]), p1 = row(x, ids[1]), p2 = row(x, ids[2]), p3 = row(x, ids[3]);
  Vec3 normal;
  if (kind == 0) {
    const Vec3 w = closest_on_triangle(p0, p1, p2, p3);
    normal = p0 - (w[0] * p1 + w[1] * p2 + w[2] * p3);
    c = SelfCollision::Contact{{ids[0], ids[1], ids[2], ids[3]}, {1.0, -w[0], -w[1], -w[2]}, Vec3::Zero(), 0.0};
  } else {
    const auto [s, t] = closest_on_segments(p0, p1, p2, p3);
    normal = (p0 + s * (p1 - p0)) - (p2 + t * (p3 - p2));
    c = SelfCollision::Contact{{ids[0], ids[1], ids[2], ids[3]}, {1.0 - s, s, -(1.0 - t), -t}, Vec3::Zero(), 0.0};
  }
  c.distance = normal.norm();
  if (c.distance <= touch) normal = kind == 0 ? Vec3((p2 - p1).cross(p3 - p1)) : Vec3((p1 - p0).cross(p3 - p2));
  c.normal = normal.squaredNorm() > 0.0 ? Vec3(normal.normalized()) : Vec3::Zero();
  return c.distance;
}

// the contact's relative velocity (first side minus second)
Vec3 relative_velocity(const SelfCollision::Contact& c, const Points& v) {
  Vec3 relative = Vec3::Zero();
  for (int k = 0; k < 4; ++k) relative += c.weight[k] * row(v, c.vertex[k]);
  return relative;
}

}  // namespace

bool SelfCollision::update_candidates(const Points& x, const Points& v, double dt, double pad,
                                      SelfCollisionStatistics& stats) {
  const Candidates& c = candidates_;
  if (c.pad < pad || c.vertex_boxes.size() != static_cast<size_t>(vertex_count_)) {
    search_all(x, v, dt, pad, stats);
    return true;
  }
  // the vertices whose start or end left their box, or whose box is more than twice as large
  // as a new one would be (the box of a fast vertex that has since slowed down)
  std::vector<int> moved;
  for (int k = 0; k < vertex_count_; ++k) {
    const Vec3 from = row(x, k) - c.frame, to = from + dt * row(v, k) - c.frame_step;
    const Box3& box = c.vertex_boxes[k];
    if (!box.contains(from) || !box.contains(to) ||
        (box.max() - box.min()).maxCoeff() > 2.0 * ((to - from).cwiseAbs().maxCoeff() + 2.0 * c.margin)) {
      moved.push_back(k);
    }
  }
  if (moved.empty()) return false;
  if (kMovedFraction * moved.size() > static_cast<size_t>(vertex_count_)) {
    search_all(x, v, dt, pad, stats);
    return true;
  }
  search_moved(x, v, dt, moved, stats);
  return false;
}

namespace {

Box3 grown(Box3 box, double by) {
  box.min().array() -= by;
  box.max().array() += by;
  return box;
}

// the box holding the boxes of `vertices`, grown by `by`
Box3 item_box(const std::vector<Box3>& vertex_boxes, const int* vertices, int count, double by) {
  Box3 box = vertex_boxes[vertices[0]];
  for (int k = 1; k < count; ++k) box.extend(vertex_boxes[vertices[k]]);
  return grown(box, by);
}

bool share_vertex(const std::array<int, 2>& a, const std::array<int, 2>& b) {
  return a[0] == b[0] || a[0] == b[1] || a[1] == b[0] || a[1] == b[1];
}

bool on_triangle(const Triangles& triangles, int t, int k) {
  return triangles(t, 0) == k || triangles(t, 1) == k || triangles(t, 2) == k;
}

constexpr double kUnmeasured = std::numeric_limits<double>::quiet_NaN();

}  // namespace

SelfCollision::Pair SelfCollision::point_triangle_pair(int k, int t) const {
  return {{k, triangles_(t, 0), triangles_(t, 1), triangles_(t, 2)}, kUnmeasured, -1, false};
}

SelfCollision::Pair SelfCollision::edge_pair(int e, int f) const {
  const int a = std::min(e, f), b = std::max(e, f);
  return {{edges_[a][0], edges_[a][1], edges_[b][0], edges_[b][1]}, kUnmeasured, -1, false};
}

bool SelfCollision::point_triangle_candidate(int k, int t) const {
  if (obstacle(k) && obstacle(triangles_(t, 0))) return false;  // an obstacle against itself
  return !on_triangle(triangles_, t, k) && point_pivot(k, t) < 0;
}

bool SelfCollision::edge_candidate(int e, int f) const {
  if (obstacle(edges_[e][0]) && obstacle(edges_[f][0])) return false;
  return !share_vertex(edges_[e], edges_[f]) && edge_pivot(e, f) < 0;
}

std::vector<SelfCollision::Pair>& SelfCollision::pair_list(int list) {
  return list < 2 ? candidates_.pairs[list] : near_.pairs[list - 2];
}

// ---- near pairs (see the top of self_collision.h)

int SelfCollision::edge_index(int a, int b) const {
  for (int i = edge_first_[a]; i < edge_first_[a + 1]; ++i) {
    const int e = vertex_edges_[i];
    if (edges_[e][0] == b || edges_[e][1] == b) return e;
  }
  return -1;
}

int SelfCollision::point_pivot(int k, int t) const {
  int pivot = -1;
  for (int j = 0; j < 3; ++j) {
    const int q = triangles_(t, j);
    if (near_.pivot[q] && (pivot < 0 || q < pivot) && edge_index(k, q) >= 0) pivot = q;
  }
  return pivot;
}

int SelfCollision::edge_pivot(int e, int f) const {
  int pivot = -1;
  const Near& m = near_;
  // a triangle on one edge whose third vertex is on the other
  for (const auto& [on, other] : {std::pair<int, int>{e, f}, std::pair<int, int>{f, e}}) {
    for (int i = m.edge_first[on]; i < m.edge_first[on + 1]; ++i) {
      const int q = m.edge_opposite[i];
      if ((q == edges_[other][0] || q == edges_[other][1]) && m.pivot[q] && (pivot < 0 || q < pivot)) pivot = q;
    }
  }
  return pivot;
}

void SelfCollision::build_near() {
  Near& m = near_;
  const int n = vertex_count_, nt = static_cast<int>(triangles_.rows()), ne = static_cast<int>(edges_.size());
  // each edge's triangles' third vertices
  std::vector<std::array<int, 2>> opposite;  // (edge, vertex)
  for (int t = 0; t < nt; ++t) {
    for (int j = 0; j < 3; ++j) opposite.push_back({edge_index(triangles_(t, j), triangles_(t, (j + 1) % 3)), triangles_(t, (j + 2) % 3)});
  }
  std::sort(opposite.begin(), opposite.end());
  m.edge_first.assign(ne + 1, 0);
  m.edge_opposite.clear();
  for (const auto& [e, q] : opposite) {
    ++m.edge_first[e + 1];
    m.edge_opposite.push_back(q);
  }
  for (int e = 0; e < ne; ++e) m.edge_first[e + 1] += m.edge_first[e];
  // interior vertices: every edge of q on two triangles, and q's link (the edges across its
  // triangles from it) one cycle through all of its neighbours
  m.pivot.assign(n, 0);
  std::vector<std::array<int, 2>> link;
  std::vector<char> used;
  for (int q = 0; q < cloth_vertices_; ++q) {  // an obstacle's pairs with itself are never candidates
    link.clear();
    for (int i = triangle_first_[q]; i < triangle_first_[q + 1]; ++i) {
      const int t = vertex_triangles_[i];
      std::array<int, 2> across{};
      int count = 0;
      for (int j = 0; j < 3; ++j) {
        if (triangles_(t, j) != q && count < 2) across[count++] = triangles_(t, j);
      }
      link.push_back(across);
    }
    bool closed = link.size() >= 3 && static_cast<int>(link.size()) == edge_first_[q + 1] - edge_first_[q];
    for (int i = edge_first_[q]; closed && i < edge_first_[q + 1]; ++i) {
      const int e = vertex_edges_[i];
      closed = m.edge_first[e + 1] - m.edge_first[e] == 2;
    }
    if (!closed) continue;
    used.assign(link.size(), 0);
    used[0] = 1;
    int at = link[0][1];
    size_t walked = 1;
    for (bool moved = true; moved && at != link[0][0];) {
      moved = false;
      for (size_t i = 0; i < link.size() && !moved; ++i) {
        if (used[i] || (link[i][0] != at && link[i][1] != at)) continue;
        used[i] = 1;
        at = link[i][0] == at ? link[i][1] : link[i][0];
        ++walked;
        moved = true;
      }
    }
    m.pivot[q] = at == link[0][0] && walked == link.size();
  }
  // each pivot's pairs
  for (int kind = 0; kind < 2; ++kind) {
    m.first[kind].assign(n + 1, 0);
    m.items[kind].clear();
  }
  for (int q = 0; q < n; ++q) {
    if (m.pivot[q]) {
      for (int i = triangle_first_[q]; i < triangle_first_[q + 1]; ++i) {
        const int t = vertex_triangles_[i];
        // points next to q against q's triangle t
        for (int j = edge_first_[q]; j < edge_first_[q + 1]; ++j) {
          const auto& e = edges_[vertex_edges_[j]];
          const int k = e[0] == q ? e[1] : e[0];
          if (!on_triangle(triangles_, t, k) && point_pivot(k, t) == q) m.items[0].push_back({k, t});
        }
        // the edge across t from q against q's edges outside t
        int a = -1, b = -1;
        for (int j = 0; j < 3; ++j) {
          if (triangles_(t, j) == q) {
            a = triangles_(t, (j + 1) % 3);
            b = triangles_(t, (j + 2) % 3);
          }
        }
        const int across = edge_index(a, b);
        for (int j = edge_first_[q]; j < edge_first_[q + 1]; ++j) {
          const int f = vertex_edges_[j];
          if (on_triangle(triangles_, t, edges_[f][0]) && on_triangle(triangles_, t, edges_[f][1])) continue;
          if (edge_pivot(across, f) == q) m.items[1].push_back({std::min(across, f), std::max(across, f)});
        }
      }
    }
    for (int kind = 0; kind < 2; ++kind) {
      auto& items = m.items[kind];
      // a pair found twice around q (q's triangles share points and edges) counts once
      std::sort(items.begin() + m.first[kind][q], items.end());
      items.erase(std::unique(items.begin() + m.first[kind][q], items.end()), items.end());
      m.first[kind][q + 1] = static_cast<int>(items.size());
    }
  }
  m.active.assign(n, 0);
}

void SelfCollision::forget_near(const std::vector<char>* moving) {
  for (auto& pairs : near_.pairs) {
    for (Pair& p : pairs) {
      if (moving && !((*moving)[p.vertex[0]] || (*moving)[p.vertex[1]] || (*moving)[p.vertex[2]] || (*moving)[p.vertex[3]])) continue;
      p.distance = std::numeric_limits<double>::quiet_NaN();
      p.clear = -1;
      p.exact = false;
    }
  }
}

void SelfCollision::bound_normals(const Points& x, const Points& v, double dt, bool new_step) {
  Normals& m = normals_;
  const int nt = static_cast<int>(triangles_.rows());
  m.all = new_step || m.velocity.rows() != v.rows() || m.dt != dt || m.normal.size() != static_cast<size_t>(nt);
  m.changed.assign(nt, m.all);
  if (!m.all) {
    for (int k = 0; k < vertex_count_; ++k) {
      if (v.row(k) == m.velocity.row(k)) continue;
      for (int i = triangle_first_[k]; i < triangle_first_[k + 1]; ++i) m.changed[vertex_triangles_[i]] = 1;
    }
  }
  m.velocity = v;
  m.dt = dt;
  m.normal.resize(nt);
  m.largest.resize(nt);
  tbb::parallel_for(0, nt, [&](int t) {
    if (!m.changed[t]) return;
    const Vec3 a = row(x, triangles_(t, 0));
    const Vec3 e1 = row(x, triangles_(t, 1)) - a, e2 = row(x, triangles_(t, 2)) - a;
    const Vec3 da = dt * row(v, triangles_(t, 0));
    const Vec3 d1 = dt * row(v, triangles_(t, 1)) - da, d2 = dt * row(v, triangles_(t, 2)) - da;
    const Vec3 c0 = e1.cross(e2), c1 = e1.cross(d2) + d1.cross(e2), c2 = d1.cross(d2);
    const auto& b = m.normal[t] = {c0, c0 + 0.5 * c1, c0 + c1 + c2};
    m.largest[t] = std::sqrt(std::max({b[0].squaredNorm(), b[1].squaredNorm(), b[2].squaredNorm()}));
  });
}

void SelfCollision::activate_near(bool new_step, SelfCollisionStatistics& stats) {
  Near& m = near_;
  const Normals& normals = normals_;
  if (new_step) {
    for (auto& pairs : m.pairs) pairs.clear();
    std::fill(m.active.begin(), m.active.end(), 0);
  }
  // the pivots of the triangles whose normals changed
  const int nt = static_cast<int>(triangles_.rows());
  m.check.assign(vertex_count_, normals.all);
  if (!normals.all) {
    for (int t = 0; t < nt; ++t) {
      if (normals.changed[t]) {
        for (int j = 0; j < 3; ++j) m.check[triangles_(t, j)] = 1;
      }
    }
  }
  const auto flat = [&](int q) {
    Vec3 axis = Vec3::Zero();
    for (int i = triangle_first_[q]; i < triangle_first_[q + 1]; ++i) axis += normals.normal[vertex_triangles_[i]][0];
    if (!(axis.squaredNorm() > 0.0)) return false;
    axis.normalize();
    for (int i = triangle_first_[q]; i < triangle_first_[q + 1]; ++i) {
      const int t = vertex_triangles_[i];
      const auto& b = normals.normal[t];
      const double least = std::min({b[0].dot(axis), b[1].dot(axis), b[2].dot(axis)});
      if (!(least >= kFlat * normals.largest[t])) return false;
    }
    return true;
  };
  long long added = 0;
  for (int q = 0; q < vertex_count_; ++q) {
    if (!m.pivot[q] || m.active[q] || !m.check[q] || flat(q)) continue;
    m.active[q] = 1;
    for (int i = m.first[0][q]; i < m.first[0][q + 1]; ++i) {
      const auto [k, t] = m.items[0][i];
      m.pairs[0].push_back(point_triangle_pair(k, t));
    }
    for (int i = m.first[1][q]; i < m.first[1][q + 1]; ++i) {
      const auto [e, f] = m.items[1][i];
      m.pairs[1].push_back(edge_pair(e, f));
    }
    added += m.first[0][q + 1] - m.first[0][q] + m.first[1][q + 1] - m.first[1][q];
  }
  if (added > 0) start_.measured = false;
  stats.near_pairs += added;
}


// a vertex's box (in the frame): its start and end of the step, grown by the margin
Box3 SelfCollision::vertex_box(const Points& x, const Points& v, double dt, int k) const {
  const Candidates& c = candidates_;
  const Vec3 from = row(x, k) - c.frame;
  return grown(Box3(from, from).extend(from + dt * row(v, k) - c.frame_step), c.margin);
}

// ---- the broad phase: the trees (cloth/patch_tree.h)

void SelfCollision::build_trees(const Points& x) {
  const int nt = static_cast<int>(triangles_.rows());
  std::vector<int> cloth(cloth_triangles_), obstacles(nt - cloth_triangles_);
  std::iota(cloth.begin(), cloth.end(), 0);
  std::iota(obstacles.begin(), obstacles.end(), cloth_triangles_);
  trees_[0].tree = PatchTree(triangles_, std::move(cloth), x);
  trees_[1].tree = PatchTree(triangles_, std::move(obstacles), x, false);  // never tested for flatness
  // homes: a vertex's first triangle's leaf, an edge's first triangle's
  point_home_.assign(vertex_count_, Home{});
  orphans_.clear();
  for (int k = 0; k < vertex_count_; ++k) {
    if (triangle_first_[k] == triangle_first_[k + 1]) {
      orphans_.push_back(k);
    } else {
      point_home_[k] = triangle_home(vertex_triangles_[triangle_first_[k]]);
    }
  }
  edge_home_.assign(edges_.size(), Home{});
  for (size_t e = 0; e < edges_.size(); ++e) {
    const auto [a, b] = edges_[e];
    for (int i = triangle_first_[a]; i < triangle_first_[a + 1]; ++i) {
      const int t = vertex_triangles_[i];
      if (on_triangle(triangles_, t, b)) {
        edge_home_[e] = triangle_home(t);
        break;
      }
    }
  }
  for (int i = 0; i < 2; ++i) {
    Tree& tree = trees_[i];
    const int leaves = tree.tree.leaf_count();
    const auto lists = [&](const std::vector<Home>& homes, std::vector<int>& first, std::vector<int>& items) {
      first.assign(leaves + 1, 0);
      for (const Home& h : homes) {
        if (h.tree == i) ++first[h.leaf + 1];
      }
      for (int l = 0; l < leaves; ++l) first[l + 1] += first[l];
      items.resize(first[leaves]);
      std::vector<int> next(first.begin(), first.end() - 1);
      for (size_t k = 0; k < homes.size(); ++k) {
        if (homes[k].tree == i) items[next[homes[k].leaf]++] = static_cast<int>(k);
      }
    };
    lists(point_home_, tree.point_first, tree.points);
    lists(edge_home_, tree.edge_first, tree.edges);
    tree.cull.assign(leaves, -1);
  }
  trees_built_ = true;
}

SelfCollision::Home SelfCollision::triangle_home(int t) const {
  const int i = t < cloth_triangles_ ? 0 : 1;
  return {i, trees_[i].tree.leaf_of(t)};
}

int SelfCollision::skipped(const Home& home, int tree) const {
  return home.tree == tree && tree == 0 ? trees_[0].cull[home.leaf] : -1;
}

void SelfCollision::point_against_leaf(int k, const Tree& tree, int leaf, std::vector<Pair>& out) const {
  const Candidates& c = candidates_;
  const PatchTree::Node& node = tree.tree.nodes()[tree.tree.leaf_node(leaf)];
  for (int p = node.begin; p < node.end; ++p) {
    const int t = tree.tree.order()[p];
    if (c.point_boxes[k].intersects(c.triangle_boxes[t]) && point_triangle_candidate(k, t)) {
      out.push_back(point_triangle_pair(k, t));
    }
  }
}

void SelfCollision::leaf_pairs(int i, int a, int j, int b, std::array<std::vector<Pair>, 2>& out) const {
  const Candidates& c = candidates_;
  const Tree &A = trees_[i], &B = trees_[j];
  const bool same = i == j && a == b;
  for (int m = A.point_first[a]; m < A.point_first[a + 1]; ++m) point_against_leaf(A.points[m], B, b, out[0]);
  if (!same) {
    for (int m = B.point_first[b]; m < B.point_first[b + 1]; ++m) point_against_leaf(B.points[m], A, a, out[0]);
  }
  for (int m = A.edge_first[a]; m < A.edge_first[a + 1]; ++m) {
    const int e = A.edges[m];
    for (int q = same ? m + 1 : B.edge_first[b]; q < B.edge_first[b + 1]; ++q) {
      const int f = B.edges[q];
      if (c.edge_boxes[e].intersects(c.edge_boxes[f]) && edge_candidate(e, f)) out[1].push_back(edge_pair(e, f));
    }
  }
}

void SelfCollision::self_pairs(int n, const Points& x, const Points& v, double dt,
                               std::array<std::vector<Pair>, 2>& out) {
  Tree& tree = trees_[0];
  const PatchTree::Node& node = tree.tree.nodes()[n];
  if (full(out)) return;  // over the candidate budget: the search stops (start sees it)
  if (tree.tree.flat(n, normals_.normal, normals_.largest, x, v, dt)) {
    std::fill(tree.cull.begin() + node.leaf_begin, tree.cull.begin() + node.leaf_end, n);
    return;
  }
  if (node.leaf()) {
    leaf_pairs(0, node.leaf_begin, 0, node.leaf_begin, out);
    return;
  }
  self_pairs(node.child[0], x, v, dt, out);
  self_pairs(node.child[1], x, v, dt, out);
  cross_pairs(0, node.child[0], 0, node.child[1], out);
}

void SelfCollision::cross_pairs(int i, int a, int j, int b, std::array<std::vector<Pair>, 2>& out) const {
  const PatchTree::Node &na = trees_[i].tree.nodes()[a], &nb = trees_[j].tree.nodes()[b];
  if (!na.box.intersects(nb.box) || full(out)) return;
  if (na.leaf() && nb.leaf()) {
    leaf_pairs(i, na.leaf_begin, j, nb.leaf_begin, out);
  } else if (na.leaf() || (!nb.leaf() && nb.end - nb.begin > na.end - na.begin)) {
    cross_pairs(i, a, j, nb.child[0], out);
    cross_pairs(i, a, j, nb.child[1], out);
  } else {
    cross_pairs(i, na.child[0], j, b, out);
    cross_pairs(i, na.child[1], j, b, out);
  }
}

namespace {

// visit(leaf) for each leaf of `tree` whose box meets `box`, not below node `skip`
template <class Visit>
void query(const PatchTree& tree, const Box3& box, int skip, Visit&& visit) {
  if (tree.empty()) return;
  int stack[64];
  int size = 0;
  stack[size++] = 0;
  while (size > 0) {
    const int n = stack[--size];
    const PatchTree::Node& node = tree.nodes()[n];
    if (n == skip || !node.box.intersects(box)) continue;
    if (node.leaf()) {
      visit(node.leaf_begin);
    } else {
      stack[size++] = node.child[1];
      stack[size++] = node.child[0];
    }
  }
}

}  // namespace

void SelfCollision::search_all(const Points& x, const Points& v, double dt, double pad,
                               SelfCollisionStatistics& stats) {
  Candidates& c = candidates_;
  double edge_sum = 0.0;
  int cloth_edges = 0;
  for (const auto& e : edges_) {
    if (obstacle(e[0])) continue;  // the margin is the cloth's: an obstacle's edges may be long
    edge_sum += (row(x, e[0]) - row(x, e[1])).norm();
    ++cloth_edges;
  }
  const double mean_edge = cloth_edges == 0 ? 1.0 : edge_sum / cloth_edges;
  c.margin = kMargin * (mean_edge > 0.0 && std::isfinite(mean_edge) ? mean_edge : 1.0);
  c.pad = pad;
  const int n = vertex_count_, nt = static_cast<int>(triangles_.rows()), ne = static_cast<int>(edges_.size());
  c.vertex_boxes.resize(n);
  c.point_boxes.resize(n);
  c.triangle_boxes.resize(nt);
  c.edge_boxes.resize(ne);
  for (int k = 0; k < n; ++k) {
    c.vertex_boxes[k] = vertex_box(x, v, dt, k);
    c.point_boxes[k] = grown(c.vertex_boxes[k], pad / 2);
  }
  for (int t = 0; t < nt; ++t) c.triangle_boxes[t] = item_box(c.vertex_boxes, triangles_.row(t).data(), 3, pad / 2);
  for (int e = 0; e < ne; ++e) c.edge_boxes[e] = item_box(c.vertex_boxes, edges_[e].data(), 2, pad / 2);
  if (!trees_built_) build_trees(x);
  for (Tree& tree : trees_) {
    tree.tree.refit(c.triangle_boxes);
    std::fill(tree.cull.begin(), tree.cull.end(), -1);
  }
  for (auto& pairs : c.pairs) pairs.clear();
  if (!trees_[0].tree.empty()) {
    self_pairs(0, x, v, dt, c.pairs);
    if (!trees_[1].tree.empty()) cross_pairs(0, 0, 1, 0, c.pairs);
  }
  for (int k : orphans_) {
    for (int i = 0; i < 2; ++i) {
      query(trees_[i].tree, c.point_boxes[k], -1, [&](int leaf) { point_against_leaf(k, trees_[i], leaf, c.pairs[0]); });
    }
  }
  start_.proximity.clear();
  forget_near(nullptr);
  start_.measured = false;
  ++stats.searches;
  stats.candidates += static_cast<long long>(c.pairs[0].size() + c.pairs[1].size());
}

void SelfCollision::search_moved(const Points& x, const Points& v, double dt, const std::vector<int>& moved,
                                 SelfCollisionStatistics& stats) {
  Candidates& c = candidates_;
  const double half = c.pad / 2;
  std::vector<char> moving(vertex_count_, 0);
  // new boxes: the moved vertices', and their triangles' and edges'
  std::vector<int> triangles, edges;  // touched, ascending
  for (int k : moved) {
    moving[k] = 1;
    c.vertex_boxes[k] = vertex_box(x, v, dt, k);
    c.point_boxes[k] = grown(c.vertex_boxes[k], half);
    triangles.insert(triangles.end(), vertex_triangles_.begin() + triangle_first_[k],
                     vertex_triangles_.begin() + triangle_first_[k + 1]);
    edges.insert(edges.end(), vertex_edges_.begin() + edge_first_[k], vertex_edges_.begin() + edge_first_[k + 1]);
  }
  for (std::vector<int>* items : {&triangles, &edges}) {
    std::sort(items->begin(), items->end());
    items->erase(std::unique(items->begin(), items->end()), items->end());
  }
  std::vector<char> touched_edge(edges_.size(), 0);
  for (int t : triangles) c.triangle_boxes[t] = item_box(c.vertex_boxes, triangles_.row(t).data(), 3, half);
  for (int e : edges) {
    c.edge_boxes[e] = item_box(c.vertex_boxes, edges_[e].data(), 2, half);
    touched_edge[e] = 1;
  }
  for (Tree& tree : trees_) tree.tree.refit(c.triangle_boxes, triangles);
  // the pairs and the repulsion contacts with a moved vertex go (the others' boxes are as
  // they were; their distances stay measured)
  const auto moves = [&](const int* vertex) { return moving[vertex[0]] || moving[vertex[1]] || moving[vertex[2]] || moving[vertex[3]]; };
  size_t kept = 0;
  for (auto& pairs : c.pairs) {
    pairs.erase(std::remove_if(pairs.begin(), pairs.end(), [&](const Pair& p) { return moves(p.vertex.data()); }), pairs.end());
    kept += pairs.size();
  }
  auto& proximity = start_.proximity;
  proximity.erase(std::remove_if(proximity.begin(), proximity.end(), [&](const Contact& p) { return moves(p.vertex); }),
                  proximity.end());
  forget_near(&moving);
  // each leaf, in both trees, whose box meets `box`, but those below the flat node where
  // `home` is (the pairs there were left out by the full search, and still may be)
  const auto leaves_near = [&](const Box3& box, const Home& home, auto&& visit) {
    for (int i = 0; i < 2; ++i) {
      query(trees_[i].tree, box, skipped(home, i), [&](int leaf) { visit(trees_[i], leaf); });
    }
  };
  // the candidate budget: past it, the items add no more pairs (start then lets the set go;
  // whichever items ran before is of no matter: the set is over the budget at any thread count)
  std::atomic<long long> held{static_cast<long long>(kept)};
  const auto over = [&] { return held.load(std::memory_order_relaxed) > pair_limit_; };
  const auto tally = [&](size_t added) { held.fetch_add(static_cast<long long>(added), std::memory_order_relaxed); };
  // moved points against every triangle; touched triangles against the points that did not move
  parallel_collect(moved.size(), c.pairs[0], [&](size_t i, std::vector<Pair>& out) {
    if (over()) return;
    const size_t before = out.size();
    const int k = moved[i];
    leaves_near(c.point_boxes[k], point_home_[k], [&](const Tree& tree, int leaf) { point_against_leaf(k, tree, leaf, out); });
    tally(out.size() - before);
  });
  parallel_collect(triangles.size(), c.pairs[0], [&](size_t i, std::vector<Pair>& out) {
    if (over()) return;
    const size_t before = out.size();
    const int t = triangles[i];
    const auto offer = [&](int k) {
      if (!moving[k] && c.point_boxes[k].intersects(c.triangle_boxes[t]) && point_triangle_candidate(k, t)) {
        out.push_back(point_triangle_pair(k, t));
      }
    };
    leaves_near(c.triangle_boxes[t], triangle_home(t), [&](const Tree& tree, int leaf) {
      for (int m = tree.point_first[leaf]; m < tree.point_first[leaf + 1]; ++m) offer(tree.points[m]);
    });
    for (int k : orphans_) offer(k);
    tally(out.size() - before);
  });
  // touched edges against every edge (a pair of two touched edges once)
  parallel_collect(edges.size(), c.pairs[1], [&](size_t i, std::vector<Pair>& out) {
    if (over()) return;
    const size_t before = out.size();
    const int e = edges[i];
    leaves_near(c.edge_boxes[e], edge_home_[e], [&](const Tree& tree, int leaf) {
      for (int m = tree.edge_first[leaf]; m < tree.edge_first[leaf + 1]; ++m) {
        const int f = tree.edges[m];
        if ((touched_edge[f] && f <= e) || !c.edge_boxes[e].intersects(c.edge_boxes[f]) || !edge_candidate(e, f)) continue;
        out.push_back(edge_pair(e, f));
      }
    });
    tally(out.size() - before);
  });
  start_.measured = false;
  ++stats.updates;
  stats.candidates += static_cast<long long>(c.pairs[0].size() + c.pairs[1].size() - kept);
}

void SelfCollision::check_flat(const Points& x, const Points& v, double dt, SelfCollisionStatistics& stats) {
  Tree& tree = trees_[0];
  std::vector<int> nodes;
  for (int leaf = 0; leaf < static_cast<int>(tree.cull.size());) {
    const int n = tree.cull[leaf];
    if (n < 0) {
      ++leaf;
      continue;
    }
    const PatchTree::Node& node = tree.tree.nodes()[n];
    leaf = node.leaf_end;  // a node's leaves are consecutive
    bool changed = normals_.all;
    for (int p = node.begin; p < node.end && !changed; ++p) changed = normals_.changed[tree.tree.order()[p]];
    if (changed) nodes.push_back(n);
  }
  Candidates& c = candidates_;
  const size_t before = c.pairs[0].size() + c.pairs[1].size();
  for (int n : nodes) {
    if (tree.tree.flat(n, normals_.normal, normals_.largest, x, v, dt)) continue;
    const PatchTree::Node& node = tree.tree.nodes()[n];
    std::fill(tree.cull.begin() + node.leaf_begin, tree.cull.begin() + node.leaf_end, -1);
    self_pairs(n, x, v, dt, c.pairs);
  }
  const size_t added = c.pairs[0].size() + c.pairs[1].size() - before;
  if (added > 0) start_.measured = false;
  stats.candidates += static_cast<long long>(added);
}

const SelfCollision::Start& SelfCollision::start(const Points& x, const Points& v, double dt,
                                                 const SelfCollisionSettings& settings,
                                                 SelfCollisionStatistics& stats) {
  const double h = settings.thickness;
  Start& s = start_;
  Candidates& c = candidates_;
  const bool new_step = !(s.x.rows() == x.rows() && s.x == x);
  if (new_step) {
    // the frame moves on, by the median motion over this step of (at most about 1,000 of) the
    // cloth's vertices (an obstacle's, a static table's say, may outnumber them)
    c.frame += c.frame_step;
    const Eigen::Index stride = std::max<Eigen::Index>(1, cloth_vertices_ / 1024);
    std::vector<double> motion((cloth_vertices_ + stride - 1) / stride);
    for (int a = 0; a < 3 && !motion.empty(); ++a) {
      for (size_t i = 0; i < motion.size(); ++i) motion[i] = dt * v(static_cast<Eigen::Index>(i) * stride, a);
      std::nth_element(motion.begin(), motion.begin() + motion.size() / 2, motion.end());
      c.frame_step[a] = std::isfinite(motion[motion.size() / 2]) ? motion[motion.size() / 2] : 0.0;
    }
  }
  if (new_step) pass_work_ = 0;  // (a caller that holds the cloth still calls begin_step)
  // the candidate budget: the searches stop past it, and a set over it is let go
  pair_limit_ = static_cast<long long>(
      std::min(settings.candidate_budget * std::max(vertex_count_, settings.budget_vertices), 4e18));
  bound_normals(x, v, dt, new_step);
  if (!update_candidates(x, v, dt, std::max(h, collision_tolerance(settings)), stats)) check_flat(x, v, dt, stats);
  activate_near(new_step, stats);
  const long long held = static_cast<long long>(c.pairs[0].size() + c.pairs[1].size() + near_.pairs[0].size() +
                                                near_.pairs[1].size());
  stats.candidate_peak = std::max(stats.candidate_peak, held);
  if (held > pair_limit_) {
    stop_over_budget(stats);
    return s;
  }
  if (new_step || s.h != h) {
    // every pair measured again (in the same pass over the pairs that measures them)
    s.x = x;
    s.h = h;
    s.proximity.clear();
    measure(x, h, true);
  } else if (!s.measured) {
    measure(x, h, false);
  }
  return s;
}

// The distances of the pairs not yet measured: the gap between the two sides' boxes where it
// is at least h (a lower bound, for the continuous test to refine if it must), the exact
// distance otherwise; the pairs closer than h join the repulsion contacts
void SelfCollision::measure(const Points& x, double h, bool all) {
  for (int list = 0; list < 4; ++list) {
    const int kind = list % 2;
    std::vector<Pair>& pairs = pair_list(list);
    const int split = kind == 0 ? 1 : 2;
    parallel_collect(pairs.size(), start_.proximity, [&](size_t n, std::vector<Contact>& found) {
      Pair& p = pairs[n];
      if (all) {
        p.clear = -1;
        p.exact = false;
      } else if (!std::isnan(p.distance)) {
        return;
      }
      Box3 first, second;
      for (int k = 0; k < 4; ++k) (k < split ? first : second).extend(row(x, p.vertex[k]));
      const double gap = (first.min() - second.max()).cwiseMax(second.min() - first.max()).cwiseMax(0.0).norm();
      if (gap >= h) {
        p.distance = gap;
        return;
      }
      Contact c;
      p.distance = pair_contact(kind, p.vertex, x, 1e-9 * h, c);
      p.exact = true;
      // the cloth's contacts with its obstacles keep it at h from them (contact/), with
      // their friction: only a pair of the cloth's own is repelled
      const bool own = !(obstacle(p.vertex[0]) || obstacle(p.vertex[1]) || obstacle(p.vertex[2]) || obstacle(p.vertex[3]));
      if (own && c.distance < h && c.normal.squaredNorm() > 0.0) found.push_back(c);
    });
  }
  // closest first (the order does not depend on how the pairs were found)
  std::sort(start_.proximity.begin(), start_.proximity.end(), [](const Contact& a, const Contact& b) {
    return a.distance != b.distance ? a.distance < b.distance : std::lexicographical_compare(a.vertex, a.vertex + 4, b.vertex, b.vertex + 4);
  });
  start_.measured = true;
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
  // a pair whose distance minus its relative motion is above this cannot collide (the slack
  // covers round-off in the distances)
  const double reach_limit = tolerance * (1.0 + 1e-6) + 1e-12;
  std::atomic<long long> tests{0};
  // the earliest contact of a pair over the step, if any; the pair marked clear otherwise
  const std::vector<char>* yielding = settings.yielding;
  const auto test = [&](int kind, Pair& pair, std::vector<Contact>& found) {
    const std::array<int, 4>& ids = pair.vertex;
    if (yielding) {
      // an obstacle against a cloth item with a vertex it has let in: not kept apart
      bool obstacle_side = false, let_in = false;
      for (int k = 0; k < 4; ++k) {
        obstacle_side = obstacle_side || obstacle(ids[k]);
        let_in = let_in || (!obstacle(ids[k]) && (*yielding)[ids[k]]);
      }
      if (obstacle_side && let_in) return;
    }
    if (pair.clear >= m.first && m.changed[ids[0]] <= pair.clear && m.changed[ids[1]] <= pair.clear &&
        m.changed[ids[2]] <= pair.clear && m.changed[ids[3]] <= pair.clear) {
      return;  // clear at a pass since which none of its vertices' velocities changed
    }
    pair.clear = m.pass;
    Vec3 d[4];
    for (int k = 0; k < 4; ++k) d[k] = dt * row(v, ids[k]);
    // d - R: the distance minus the pair's relative motion R, a lower bound of its distance
    // over the step (the exact distance taken where the boxes' gap is not enough)
    const double r = kind == 0
        ? std::sqrt(std::max({(d[1] - d[0]).squaredNorm(), (d[2] - d[0]).squaredNorm(), (d[3] - d[0]).squaredNorm()}))
        : (d[1] - d[0]).norm() + std::sqrt(std::max((d[2] - d[0]).squaredNorm(), (d[3] - d[0]).squaredNorm()));
    if (pair.distance - reach_limit > r) return;
    if (!pair.exact) {
      Contact c;
      pair.distance = pair_contact(kind, ids, x, 0.0, c);
      pair.exact = true;
      if (pair.distance - reach_limit > r) return;
    }
    tests.fetch_add(1, std::memory_order_relaxed);
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
    if (!first.intersects(second)) return;
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
      return;  // the earliest contact of the pair
    }
  };
  for (int list = 0; list < 4; ++list) {
    const int kind = list % 2;
    std::vector<Pair>& pairs = pair_list(list);
    parallel_collect(pairs.size(), out, [&](size_t n, std::vector<Contact>& found) { test(kind, pairs[n], found); });
  }
  // earliest first (the order does not depend on how the pairs were found)
  std::sort(out.begin(), out.end(), [](const Contact& a, const Contact& b) {
    return a.time != b.time ? a.time < b.time : std::lexicographical_compare(a.vertex, a.vertex + 4, b.vertex, b.vertex + 4);
  });
  stats.tests += tests.load();
}

void SelfCollision::resolve(const Points& x, Points& v, const Eigen::VectorXd& inverse_mass, double dt,
                            const SelfCollisionSettings& settings, SelfCollisionStatistics& stats) {
  begin_step();
  repel(x, v, inverse_mass, dt, settings, stats);
  if (!collide(x, v, inverse_mass, dt, settings, stats, settings.collision_passes)) {
    impact_zones(x, v, inverse_mass, dt, settings, stats);
  }
}

void SelfCollision::begin_step() {
  pass_work_ = 0;
  over_budget_ = false;
}

void SelfCollision::stop_over_budget(SelfCollisionStatistics& stats) {
  over_budget_ = true;
  ++stats.over_budget;
  // the candidates let go (all found again at the next step: the set over the budget, or cut
  // short, is no good to keep), and the step's start forgotten
  for (auto& pairs : candidates_.pairs) std::vector<Pair>().swap(pairs);
  for (auto& pairs : near_.pairs) pairs.clear();
  std::fill(near_.active.begin(), near_.active.end(), 0);
  candidates_.pad = -1.0;
  start_.x.resize(0, 3);
  start_.proximity.clear();
  start_.measured = false;
}

void SelfCollision::repel(const Points& x, Points& v, const Eigen::VectorXd& inverse_mass, double dt,
                          const SelfCollisionSettings& settings, SelfCollisionStatistics& stats) {
  const double h = settings.thickness;
  if (!(h > 0.0) || over_budget_) return;
  const std::vector<Contact>& contacts = start(x, v, dt, settings, stats).proximity;
  if (over_budget_) return;
  // pairs in touch: the normal across both sides, turned against their approach now (before
  // any of this pass's impulses)
  std::vector<std::pair<size_t, Vec3>> touching;
  for (size_t k = 0; k < contacts.size(); ++k) {
    const Contact& c = contacts[k];
    if (c.distance <= 1e-9 * h) touching.emplace_back(k, relative_velocity(c, v).dot(c.normal) > 0.0 ? Vec3(-c.normal) : c.normal);
  }
  auto next = touching.begin();
  for (size_t k = 0; k < contacts.size(); ++k) {
    Contact c = contacts[k];
    if (next != touching.end() && next->first == k) c.normal = (next++)->second;
    stats.repulsions += apply_impulse(c, kRepulsionRate * (h - c.distance) / dt, settings.friction, v, inverse_mass,
                                      settings.support);
  }
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

namespace {

// A zone's vertices given one rigid motion, that of the zone's momentum and angular momentum
// about its centre of mass, with `impulse` (n x 3, N s, if any) added to its vertices' own. A
// zone holding vertices of infinite mass moves as they do: those of one obstacle (obstacle_of
// >= 0) give the zone that obstacle's motion (motions[obstacle]), which carries the zone and
// the obstacle by one invertible affine map, so that nothing in the zone passes through the
// obstacle; a pinned cloth vertex, or two obstacles, hold the zone still, and so does the
// surface under it where the obstacle would carry one of its vertices into that surface
// faster than `sink` (m/s): the obstacle then passes through the cloth (returns true).
// Vertices of infinite mass keep their own velocities.
bool move_rigidly(const std::vector<int>& zone, const Points& x, Points& v, const Eigen::VectorXd& inverse_mass,
                  const Points* impulse, const std::vector<int>& obstacle_of, int cloth_vertices,
                  const std::vector<ObstacleMotion>* motions, const std::vector<Vec3>* support, double sink) {
  int held_by = -1;       // the obstacle the zone holds, if one
  bool still = false;     // a pinned vertex, or two obstacles
  for (int i : zone) {
    if (inverse_mass[i] > 0.0) continue;
    const int o = i >= cloth_vertices && motions ? obstacle_of[i - cloth_vertices] : -1;
    if (o < 0 || (held_by >= 0 && held_by != o)) still = true;
    held_by = o;
  }
  if (still || held_by >= 0) {
    const ObstacleMotion* motion = still ? nullptr : &(*motions)[held_by];
    // An obstacle that would carry a vertex of the zone into the still surface it rests on (a
    // keyed box pressing the cloth into the ground) cannot be followed: the cloth cannot be in
    // two places. The surface holds the zone, as a pin would, and the obstacle passes through
    // the cloth there (from the next step on, its contacts and self-collision leave the
    // vertices inside it alone: cloth_body_contact.cpp, SelfCollisionSettings::yielding).
    // Followed, the zone went under the ground with the box, the edges from it to the cloth
    // the ground held stretched by the box's travel every step (strain 5.3 after 0.16 s at
    // 1 m/s), and the candidate pairs, the searches and the step's work with them doubled
    // every frame until the cloth blew up (issue 30; benchmarks/stress/cloth_press.py)
    bool yields = false;
    for (int i : zone) {
      if (!motion || !support || inverse_mass[i] <= 0.0 || !((*support)[i].squaredNorm() > 0.0)) continue;
      yields = yields || Vec3(motion->A * row(x, i) + motion->c).dot((*support)[i].normalized()) < -sink;
    }
    if (yields) motion = nullptr;
    for (int i : zone) {
      if (inverse_mass[i] <= 0.0) continue;
      const Vec3 velocity = motion ? Vec3(motion->A * row(x, i) + motion->c) : Vec3::Zero();
      v.row(i) = velocity.transpose();
    }
    return yields;
  }
  double mass = 0.0;
  Vec3 center = Vec3::Zero(), momentum = Vec3::Zero();
  for (int i : zone) {
    const double m = 1.0 / inverse_mass[i];
    mass += m;
    center += m * row(x, i);
    momentum += m * row(v, i);
    if (impulse) momentum += row(*impulse, i);
  }
  center /= mass;
  const Vec3 velocity = momentum / mass;
  Vec3 angular = Vec3::Zero();
  Mat3 inertia = Mat3::Zero();
  for (int i : zone) {
    const double m = 1.0 / inverse_mass[i];
    const Vec3 r = row(x, i) - center;
    angular += m * r.cross(row(v, i) - velocity);
    if (impulse) angular += r.cross(row(*impulse, i));
    inertia += m * (r.squaredNorm() * Mat3::Identity() - r * r.transpose());
  }
  // a zone on one line has no inertia about it: the pseudo-inverse leaves that spin out
  const Vec3 omega = inertia.completeOrthogonalDecomposition().solve(angular);
  const auto rigid = [&](int i) { return Vec3(velocity + omega.cross(row(x, i) - center)); };
  // a zone whose motion would take a vertex into the still surface it rests on holds still
  // instead: the surface holds it as a pin would
  bool into_support = false;
  if (support) {
    for (int i : zone) into_support = into_support || rigid(i).dot((*support)[i]) < 0.0;
  }
  for (int i : zone) v.row(i) = (into_support ? Vec3::Zero() : rigid(i)).transpose();
  return false;
}

}  // namespace

std::vector<std::vector<int>> SelfCollision::zone_members() const {
  std::vector<std::vector<int>> zones(vertex_count_);
  for (int i = 0; i < vertex_count_; ++i) {
    if (!in_zone_[i]) continue;
    int root = i;
    while (zone_parent_[root] != root) root = zone_parent_[root];
    zones[root].push_back(i);
  }
  return zones;
}

void SelfCollision::push_zones(const Points& x, Points& v, const Eigen::VectorXd& inverse_mass,
                               const SelfCollisionSettings& settings, const Points& impulse) const {
  if (over_budget_) return;
  // (the zones that gave way to an obstacle in impact_zones give way again: the same step)
  const double sink = collision_tolerance(settings) / passes_.dt;
  for (const std::vector<int>& zone : zone_members()) {
    if (!zone.empty()) move_rigidly(zone, x, v, inverse_mass, &impulse, obstacle_of_, cloth_vertices_, settings.obstacle_motion, settings.support, sink);
  }
}

void SelfCollision::impact_zones(const Points& x, Points& v, const Eigen::VectorXd& inverse_mass, double dt,
                                 const SelfCollisionSettings& settings, SelfCollisionStatistics& stats) {
  std::vector<Contact> contacts;
  // 3. rigid impact zones until nothing collides
  std::vector<int>& parent = zone_parent_;
  parent.resize(vertex_count_);
  std::iota(parent.begin(), parent.end(), 0);
  in_zone_.assign(vertex_count_, 0);
  if (over_budget_) return;
  std::vector<char>& in_zone = in_zone_;
  // an obstacle carrying a zone into the surface under it more than the collision tolerance
  // over the step gives way (move_rigidly)
  const double sink = collision_tolerance(settings) / dt;
  const auto find = [&](int i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  };
  // a pair inside one zone moves with it by an invertible affine map, which passes nothing
  // through anything: only pairs reaching outside a zone are left to resolve
  const auto outside_zones = [&](std::vector<Contact>& list) {
    list.erase(std::remove_if(list.begin(), list.end(), [&](const Contact& c) {
                 const int zone = find(c.vertex[0]);
                 if (!in_zone[c.vertex[0]]) return false;
                 for (int k = 1; k < 4; ++k) {
                   if (!in_zone[c.vertex[k]] || find(c.vertex[k]) != zone) return false;
                 }
                 return true;
               }), list.end());
  };
  for (int round = 0; round < settings.zone_iterations; ++round) {
    collision_contacts(x, v, dt, settings, contacts, stats);
    outside_zones(contacts);
    if (contacts.empty()) return;
    ++stats.zone_rounds;
    stats.zone_round_peak = std::max<long long>(stats.zone_round_peak, round + 1);
    for (const Contact& c : contacts) {
      for (int k = 0; k < 4; ++k) {
        in_zone[c.vertex[k]] = 1;
        const int a = find(c.vertex[0]), b = find(c.vertex[k]);
        if (a != b) parent[std::max(a, b)] = std::min(a, b);
      }
    }
    // each zone's rigid motion: momentum and angular momentum about its centre of mass kept
    for (const std::vector<int>& zone : zone_members()) {
      if (zone.empty()) continue;
      stats.zone_vertices += static_cast<long long>(zone.size());
      stats.yields += move_rigidly(zone, x, v, inverse_mass, nullptr, obstacle_of_, cloth_vertices_,
                                   settings.obstacle_motion, settings.support, sink);
    }
  }
  // the last resort: the cloth does not move, and a cloth free of crossings stays free of them
  // (unless a moving obstacle runs into it: obstacles move as they must)
  collision_contacts(x, v, dt, settings, contacts, stats);
  if (over_budget_) return;  // (the caller holds the cloth still)
  outside_zones(contacts);
  if (contacts.empty()) return;
  ++stats.stills;
  v.topRows(cloth_vertices_).setZero();
}

}  // namespace simbake
