#include "cloth/self_collision.h"

#include "geometry/mesh.h"

#include <Eigen/Dense>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numeric>

namespace simbake {

namespace {

constexpr double kRepulsionRate = 0.1;      // a pair closer than h separates by 0.1 (h - d) per step at most
constexpr double kCollisionTolerance = 1e-2; // of h: coplanar pairs this close count as colliding
constexpr double kSeparation = 1e-3;        // of h per step: the separating speed a collision impulse leaves
constexpr long long kMaxCells = 4096;       // a query over more grid cells scans every item
constexpr double kMargin = 0.1;             // of the mean edge: how far motions may drift before
                                            // the candidate pairs are found again
constexpr size_t kChunk = 512;              // pairs per parallel task (fixed: same result at any thread count)

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

// Parameters (s, t) in [0, 1] of the closest points of segments p0 p1 and q0 q1
// (Ericson 5.1.9)
std::pair<double, double> closest_on_segments(const Vec3& p0, const Vec3& p1, const Vec3& q0, const Vec3& q1) {
  const Vec3 d1 = p1 - p0, d2 = q1 - q0, r = p0 - q0;
  const double a = d1.squaredNorm(), e = d2.squaredNorm(), f = d2.dot(r);
  constexpr double kTiny = 1e-30;
  if (a <= kTiny && e <= kTiny) return {0.0, 0.0};
  double s, t;
  if (a <= kTiny) {
    s = 0.0;
    t = std::clamp(f / e, 0.0, 1.0);
  } else {
    const double c = d1.dot(r);
    if (e <= kTiny) {
      t = 0.0;
      s = std::clamp(-c / a, 0.0, 1.0);
    } else {
      const double b = d1.dot(d2), denom = a * e - b * b;
      s = denom > kTiny * a * e ? std::clamp((b * f - c * e) / denom, 0.0, 1.0) : 0.0;
      t = (b * s + f) / e;
      if (t < 0.0) {
        t = 0.0;
        s = std::clamp(-c / a, 0.0, 1.0);
      } else if (t > 1.0) {
        t = 1.0;
        s = std::clamp((b - c) / a, 0.0, 1.0);
      }
    }
  }
  return {s, t};
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

Box3 swept_box(const Points& x, const Points& v, double dt, const int* vertices, int count, double pad) {
  Box3 box;
  for (int k = 0; k < count; ++k) {
    box.extend(row(x, vertices[k]));
    box.extend(row(x, vertices[k]) + dt * row(v, vertices[k]));
  }
  box.min().array() -= pad;
  box.max().array() += pad;
  return box;
}

// Applies an impulse along the contact's normal that brings the pair's relative normal
// velocity up to `target` (never down), with Coulomb friction on the relative slip limited
// by the same change; returns whether it did anything
bool apply_impulse(const SelfCollision::Contact& c, double target, double friction, Points& v,
                   const Eigen::VectorXd& inverse_mass) {
  double denom = 0.0;
  Vec3 relative = Vec3::Zero();
  for (int k = 0; k < 4; ++k) {
    denom += c.weight[k] * c.weight[k] * inverse_mass[c.vertex[k]];
    relative += c.weight[k] * row(v, c.vertex[k]);
  }
  if (denom <= 0.0) return false;
  const double vn = relative.dot(c.normal);
  const double change = target - vn;
  if (!(change > 0.0)) return false;
  Vec3 delta = change * c.normal;  // the wanted change of the relative velocity
  const Vec3 slip = relative - vn * c.normal;
  const double slip_speed = slip.norm();
  if (slip_speed > 0.0) delta -= std::min(1.0, friction * change / slip_speed) * slip;
  for (int k = 0; k < 4; ++k) {
    const int i = c.vertex[k];
    v.row(i) += (c.weight[k] * inverse_mass[i] / denom) * delta.transpose();
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

// A uniform grid over boxes, each item entered once, in the cell of its box's centre; the
// cell is as large as the largest box (at most 4 x the median box: larger boxes, of fast
// vertices, are kept aside and offered to every query). A box meets a query's box only if
// its centre lies within half a cell of it, so a query scans the cells there and visits each
// item at most once; queries share nothing and may run in parallel.
class SelfCollision::Grid {
 public:
  explicit Grid(const std::vector<Box3>& boxes) : boxes_(boxes) {
    const int n = static_cast<int>(boxes.size());
    std::vector<double> extents(n);
    for (int i = 0; i < n; ++i) extents[i] = (boxes[i].max() - boxes[i].min()).maxCoeff();
    std::vector<double> sorted = extents;
    if (n > 0) std::nth_element(sorted.begin(), sorted.begin() + n / 2, sorted.end());
    const double median = n > 0 ? sorted[n / 2] : 1.0;
    cell_ = 0.0;
    for (double e : extents) {
      if (e <= 4.0 * median) cell_ = std::max(cell_, e);
    }
    if (!(cell_ > 0.0 && std::isfinite(cell_))) cell_ = std::isfinite(median) && median > 0.0 ? median : 1.0;
    entries_.reserve(n);
    for (int i = 0; i < n; ++i) {
      Cell c;
      if (!(extents[i] <= cell_) || !cell_of(boxes[i].center(), c)) {
        large_.push_back(i);
        continue;
      }
      entries_.emplace_back(key(c), i);
    }
    std::sort(entries_.begin(), entries_.end());
  }

  // visit(i, j), i < j, once for every pair of the grid's own items whose boxes meet: each
  // cell against itself and its 13 neighbours ahead of it (centres of meeting boxes lie at
  // most a cell apart), cells in parallel in fixed chunks, the pairs in cell order
  template <class Visit>
  void self_pairs(std::vector<std::pair<int, int>>& out, Visit&& keep) const {
    std::vector<size_t> starts;  // first entry of each non-empty cell
    for (size_t e = 0; e < entries_.size(); ++e) {
      if (e == 0 || entries_[e].first != entries_[e - 1].first) starts.push_back(e);
    }
    starts.push_back(entries_.size());
    static const int ahead[13][3] = {{1, 0, 0},  {-1, 1, 0}, {0, 1, 0},  {1, 1, 0},  {-1, -1, 1},
                                     {0, -1, 1}, {1, -1, 1}, {-1, 0, 1}, {0, 0, 1},  {1, 0, 1},
                                     {-1, 1, 1}, {0, 1, 1},  {1, 1, 1}};
    const auto offer = [&](int i, int j, std::vector<std::pair<int, int>>& found) {
      if (boxes_[i].intersects(boxes_[j]) && keep(std::min(i, j), std::max(i, j))) {
        found.emplace_back(std::min(i, j), std::max(i, j));
      }
    };
    parallel_collect(starts.size() - 1, out, [&](size_t k, std::vector<std::pair<int, int>>& found) {
      const size_t begin = starts[k], end = starts[k + 1];
      for (size_t p = begin; p < end; ++p)
        for (size_t q = p + 1; q < end; ++q) offer(entries_[p].second, entries_[q].second, found);
      const Cell here = unkey(entries_[begin].first);
      for (const auto& d : ahead) {
        const Cell there{here[0] + d[0], here[1] + d[1], here[2] + d[2]};
        auto it = std::lower_bound(entries_.begin(), entries_.end(), std::make_pair(key(there), -1));
        for (; it != entries_.end() && it->first == key(there); ++it)
          for (size_t p = begin; p < end; ++p) offer(entries_[p].second, it->second, found);
      }
    });
    // items kept aside against everything (a pair of two of them once)
    for (size_t a = 0; a < large_.size(); ++a) {
      const int i = large_[a];
      for (int j = 0; j < static_cast<int>(boxes_.size()); ++j) {
        const bool also_large = std::binary_search(large_.begin(), large_.end(), j);
        if (j == i || (also_large && j < i)) continue;
        offer(i, j, out);
      }
    }
  }

  // visit(item) once for every item whose box meets `box`
  template <class Visit>
  void query(const Box3& box, Visit&& visit) const {
    for (int item : large_) {
      if (boxes_[item].intersects(box)) visit(item);
    }
    Cell lo, hi;
    const Vec3 half = Vec3::Constant(cell_ / 2);
    long long count = 1;
    if (cell_of(box.min() - half, lo) && cell_of(box.max() + half, hi)) {
      for (int k = 0; k < 3; ++k) count *= static_cast<long long>(hi[k]) - lo[k] + 1;
    } else {
      count = kMaxCells + 1;
    }
    if (count > kMaxCells) {  // a huge query: every item
      for (const auto& [k, item] : entries_) {
        if (boxes_[item].intersects(box)) visit(item);
      }
      return;
    }
    for (int a = lo[0]; a <= hi[0]; ++a)
      for (int b = lo[1]; b <= hi[1]; ++b)
        for (int c = lo[2]; c <= hi[2]; ++c) {
          const std::uint64_t k = key(Cell{a, b, c});
          auto it = std::lower_bound(entries_.begin(), entries_.end(), std::make_pair(k, -1));
          for (; it != entries_.end() && it->first == k; ++it) {
            if (boxes_[it->second].intersects(box)) visit(it->second);
          }
        }
  }

 private:
  using Cell = std::array<int, 3>;
  const std::vector<Box3>& boxes_;
  double cell_ = 1.0;
  std::vector<std::pair<std::uint64_t, int>> entries_;
  std::vector<int> large_;

  bool cell_of(const Vec3& p, Cell& c) const {
    for (int k = 0; k < 3; ++k) {
      const double a = p[k] / cell_;
      if (!(std::abs(a) < 1e6)) return false;
      c[k] = static_cast<int>(std::floor(a));
    }
    return true;
  }
  static std::uint64_t key(const Cell& c) {
    const auto bits = [](int v) { return static_cast<std::uint64_t>(v + (1 << 20)) & 0x1FFFFF; };
    return bits(c[0]) << 42 | bits(c[1]) << 21 | bits(c[2]);
  }
  static Cell unkey(std::uint64_t k) {
    const auto value = [](std::uint64_t bits) { return static_cast<int>(bits & 0x1FFFFF) - (1 << 20); };
    return Cell{value(k >> 42), value(k >> 21), value(k)};
  }
};


SelfCollision::SelfCollision(const Triangles& triangles, int vertex_count)
    : triangles_(triangles), edges_(unique_edges(triangles)), vertex_count_(vertex_count) {}

const SelfCollision::Candidates& SelfCollision::candidates(const Points& x, const Points& v, double dt, double pad,
                                                          SelfCollisionStatistics& stats) {
  Candidates& c = candidates_;
  // still valid: the same start, a pad at least as large, motions within the margin
  if (c.pad >= pad && c.x.rows() == x.rows() && c.x == x) {
    double drift = 0.0;
    for (Eigen::Index k = 0; k < x.rows() && drift <= c.margin; ++k) {
      drift = std::max(drift, (dt * v.row(k) - c.motion.row(k)).cwiseAbs().maxCoeff());
    }
    if (drift <= c.margin) return c;
  }
  c.x = x;
  c.motion = dt * v;
  c.pad = pad;
  double edge_sum = 0.0;
  for (const auto& e : edges_) edge_sum += (row(x, e[0]) - row(x, e[1])).norm();
  const double mean_edge = edges_.empty() ? 1.0 : edge_sum / edges_.size();
  c.margin = kMargin * (mean_edge > 0.0 && std::isfinite(mean_edge) ? mean_edge : 1.0);
  c.point_triangle.clear();
  c.edge_edge.clear();
  const double grow = pad + c.margin;
  const int nt = static_cast<int>(triangles_.rows()), ne = static_cast<int>(edges_.size());
  std::vector<Box3> triangle_boxes(nt), edge_boxes(ne);
  for (int t = 0; t < nt; ++t) triangle_boxes[t] = swept_box(x, v, dt, triangles_.row(t).data(), 3, grow);
  for (int e = 0; e < ne; ++e) edge_boxes[e] = swept_box(x, v, dt, edges_[e].data(), 2, grow);
  // points against triangles
  const Grid triangle_grid(triangle_boxes);
  parallel_collect(vertex_count_, c.point_triangle, [&](size_t i, std::vector<std::pair<int, int>>& out) {
    const int k = static_cast<int>(i);
    triangle_grid.query(swept_box(x, v, dt, &k, 1, grow), [&](int t) {
      if (triangles_(t, 0) != k && triangles_(t, 1) != k && triangles_(t, 2) != k) out.emplace_back(k, t);
    });
  });
  // edges against edges, each pair once
  const Grid edge_grid(edge_boxes);
  edge_grid.self_pairs(c.edge_edge, [&](int e, int f) {
    const auto& a = edges_[e];
    const auto& b = edges_[f];
    return !(a[0] == b[0] || a[0] == b[1] || a[1] == b[0] || a[1] == b[1]);
  });
  ++stats.searches;
  stats.candidates += static_cast<long long>(c.point_triangle.size() + c.edge_edge.size());
  return c;
}

void SelfCollision::proximity_contacts(const Points& x, const Points& v, double dt, double h,
                                       std::vector<Contact>& out, SelfCollisionStatistics& stats) {
  out.clear();
  const Candidates& c = candidates(x, v, dt, h, stats);
  parallel_collect(c.point_triangle.size(), out, [&](size_t n, std::vector<Contact>& found) {
    const auto [i, j] = c.point_triangle[n];
    const int a = triangles_(j, 0), b = triangles_(j, 1), d = triangles_(j, 2);
    const Vec3 p = row(x, i);
    const Vec3 w = closest_on_triangle(p, row(x, a), row(x, b), row(x, d));
    const Vec3 q = w[0] * row(x, a) + w[1] * row(x, b) + w[2] * row(x, d);
    const double distance = (p - q).norm();
    if (distance >= h) return;
    Vec3 normal = p - q;
    if (distance <= 1e-9 * h) {  // touching: the triangle's normal, against the approach
      normal = (row(x, b) - row(x, a)).cross(row(x, d) - row(x, a));
      const Vec3 relative = row(v, i) - (w[0] * row(v, a) + w[1] * row(v, b) + w[2] * row(v, d));
      if (relative.dot(normal) > 0.0) normal = -normal;
    }
    if (normal.squaredNorm() == 0.0) return;
    found.push_back(Contact{{i, a, b, d}, {1.0, -w[0], -w[1], -w[2]}, normal.normalized(), distance});
  });
  parallel_collect(c.edge_edge.size(), out, [&](size_t n, std::vector<Contact>& found) {
    const auto& e = edges_[c.edge_edge[n].first];
    const auto& f = edges_[c.edge_edge[n].second];
    const Vec3 p0 = row(x, e[0]), p1 = row(x, e[1]), q0 = row(x, f[0]), q1 = row(x, f[1]);
    const auto [s, t] = closest_on_segments(p0, p1, q0, q1);
    Vec3 normal = (p0 + s * (p1 - p0)) - (q0 + t * (q1 - q0));
    const double distance = normal.norm();
    if (distance >= h) return;
    if (distance <= 1e-9 * h) {  // touching: across both edges, against the approach
      normal = (p1 - p0).cross(q1 - q0);
      const Vec3 relative = (1 - s) * row(v, e[0]) + s * row(v, e[1]) - (1 - t) * row(v, f[0]) - t * row(v, f[1]);
      if (relative.dot(normal) > 0.0) normal = -normal;
    }
    if (normal.squaredNorm() == 0.0) return;
    found.push_back(Contact{{e[0], e[1], f[0], f[1]}, {1.0 - s, s, -(1.0 - t), -t}, normal.normalized(), distance});
  });
}

void SelfCollision::collision_contacts(const Points& x, const Points& v, double dt, double tolerance,
                                       std::vector<Contact>& out, SelfCollisionStatistics& stats) {
  out.clear();
  const Candidates& cand = candidates(x, v, dt, tolerance, stats);
  const auto test = [&](int kind, const int ids[4], std::vector<Contact>& found) {
    Vec3 p[4], d[4];
    for (int k = 0; k < 4; ++k) {
      p[k] = row(x, ids[k]);
      d[k] = dt * row(v, ids[k]);
    }
    // the two sides' boxes over the step, now (the candidates were found with a margin)
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
      found.push_back(c);
      return;  // the earliest contact of the pair
    }
  };
  parallel_collect(cand.point_triangle.size(), out, [&](size_t n, std::vector<Contact>& found) {
    const auto [i, j] = cand.point_triangle[n];
    const int ids[4] = {i, triangles_(j, 0), triangles_(j, 1), triangles_(j, 2)};
    test(0, ids, found);
  });
  parallel_collect(cand.edge_edge.size(), out, [&](size_t n, std::vector<Contact>& found) {
    const auto& e = edges_[cand.edge_edge[n].first];
    const auto& f = edges_[cand.edge_edge[n].second];
    const int ids[4] = {e[0], e[1], f[0], f[1]};
    test(1, ids, found);
  });
}

void SelfCollision::resolve(const Points& x, Points& v, const Eigen::VectorXd& inverse_mass, double dt,
                            const SelfCollisionSettings& settings, SelfCollisionStatistics& stats) {
  repel(x, v, inverse_mass, dt, settings, stats);
  if (!collide(x, v, inverse_mass, dt, settings, stats, settings.collision_passes)) {
    impact_zones(x, v, inverse_mass, dt, settings, stats);
  }
}

void SelfCollision::repel(const Points& x, Points& v, const Eigen::VectorXd& inverse_mass, double dt,
                          const SelfCollisionSettings& settings, SelfCollisionStatistics& stats) {
  const double h = settings.thickness;
  if (!(h > 0.0)) return;
  std::vector<Contact> contacts;
  proximity_contacts(x, v, dt, h, contacts, stats);
  for (const Contact& c : contacts) {
    stats.repulsions += apply_impulse(c, kRepulsionRate * (h - c.distance) / dt, settings.friction, v, inverse_mass);
  }
}

bool SelfCollision::collide(const Points& x, Points& v, const Eigen::VectorXd& inverse_mass, double dt,
                            const SelfCollisionSettings& settings, SelfCollisionStatistics& stats, int passes) {
  const double tolerance = collision_tolerance(settings);
  const double separation = kSeparation * settings.thickness / dt;
  std::vector<Contact> contacts;
  for (int pass = 0; pass < passes; ++pass) {
    collision_contacts(x, v, dt, tolerance, contacts, stats);
    if (contacts.empty()) return true;
    for (const Contact& c : contacts) stats.collisions += apply_impulse(c, separation, settings.friction, v, inverse_mass);
  }
  return false;
}

void SelfCollision::impact_zones(const Points& x, Points& v, const Eigen::VectorXd& inverse_mass, double dt,
                                 const SelfCollisionSettings& settings, SelfCollisionStatistics& stats) {
  const double tolerance = collision_tolerance(settings);
  std::vector<Contact> contacts;
  // 3. rigid impact zones until nothing collides
  std::vector<int> parent(vertex_count_);
  std::iota(parent.begin(), parent.end(), 0);
  in_zone_.assign(vertex_count_, 0);
  std::vector<char>& in_zone = in_zone_;
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
    collision_contacts(x, v, dt, tolerance, contacts, stats);
    outside_zones(contacts);
    if (contacts.empty()) return;
    ++stats.zone_rounds;
    for (const Contact& c : contacts) {
      for (int k = 0; k < 4; ++k) {
        in_zone[c.vertex[k]] = 1;
        const int a = find(c.vertex[0]), b = find(c.vertex[k]);
        if (a != b) parent[std::max(a, b)] = std::min(a, b);
      }
    }
    // each zone's rigid motion: momentum and angular momentum about its centre of mass kept
    std::vector<std::vector<int>> zones(vertex_count_);
    for (int i = 0; i < vertex_count_; ++i) {
      if (in_zone[i]) zones[find(i)].push_back(i);
    }
    for (const std::vector<int>& zone : zones) {
      if (zone.empty()) continue;
      stats.zone_vertices += static_cast<long long>(zone.size());
      bool fixed = false;
      double mass = 0.0;
      Vec3 center = Vec3::Zero(), momentum = Vec3::Zero();
      for (int i : zone) {
        if (inverse_mass[i] <= 0.0) {
          fixed = true;
          break;
        }
        const double m = 1.0 / inverse_mass[i];
        mass += m;
        center += m * row(x, i);
        momentum += m * row(v, i);
      }
      if (fixed) {
        for (int i : zone) v.row(i).setZero();
        continue;
      }
      center /= mass;
      const Vec3 velocity = momentum / mass;
      Vec3 angular = Vec3::Zero();
      Mat3 inertia = Mat3::Zero();
      for (int i : zone) {
        const double m = 1.0 / inverse_mass[i];
        const Vec3 r = row(x, i) - center;
        angular += m * r.cross(row(v, i) - velocity);
        inertia += m * (r.squaredNorm() * Mat3::Identity() - r * r.transpose());
      }
      // a zone on one line has no inertia about it: the pseudo-inverse leaves that spin out
      const Vec3 omega = inertia.completeOrthogonalDecomposition().solve(angular);
      for (int i : zone) v.row(i) = (velocity + omega.cross(row(x, i) - center)).transpose();
    }
  }
  // the last resort: nothing moves, and a cloth free of crossings stays free of them
  collision_contacts(x, v, dt, tolerance, contacts, stats);
  outside_zones(contacts);
  if (contacts.empty()) return;
  ++stats.stills;
  v.setZero();
}

}  // namespace simbake
