// Self-collision's near pairs (the argument is at the top of self_collision.h): the pairs of
// neighbouring elements around each interior vertex, candidates only where its triangles are
// not flat over the step, and each triangle's normal over the step, bounded.
#include "cloth/self_collision.h"

#include "cloth/self_collision_detail.h"

#include <cmath>

namespace simbake {

using namespace self_collision_detail;

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

}  // namespace simbake
