// Self-collision's plumbing: the joined arrays of the cloth and its obstacles, each vertex's
// triangles and edges, the step's start (every candidate's distance, the pairs closer than the
// thickness), and the three parts in turn (the method is at the top of self_collision.h).
#include "cloth/self_collision.h"

#include "cloth/self_collision_detail.h"
#include "geometry/closest_points.h"
#include "geometry/mesh.h"

#include <cmath>

namespace simbake {

using namespace self_collision_detail;

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

namespace self_collision_detail {

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

}  // namespace self_collision_detail

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

}  // namespace simbake
