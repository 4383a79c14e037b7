#include "cloth/patch_tree.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <utility>

namespace simbake {

namespace {

constexpr int kLeafTriangles = 8;
constexpr double kFlat = 0.1;   // normals within acos(0.1) = 84 degrees of the axis (as the near pairs' pivots)
constexpr double kRoom = 1e-6;  // of the largest coefficient: the room the star's areas leave for round-off

}  // namespace

PatchTree::PatchTree(const Triangles& triangles, std::vector<int> ids, const Points& x, bool patches) {
  leaf_of_.assign(triangles.rows(), -1);
  if (ids.empty()) return;
  std::vector<Vec3> centroid(triangles.rows(), Vec3::Zero());
  for (int t : ids) {
    const Vec3 c = (x.row(triangles(t, 0)) + x.row(triangles(t, 1)) + x.row(triangles(t, 2))).transpose() / 3.0;
    if (c.allFinite()) centroid[t] = c;
  }
  build(ids, 0, static_cast<int>(ids.size()), -1, centroid);
  order_ = std::move(ids);
  if (patches) find_loops(triangles, x);
}

int PatchTree::build(std::vector<int>& ids, int begin, int end, int parent, const std::vector<Vec3>& centroid) {
  const int n = static_cast<int>(nodes_.size());
  nodes_.emplace_back();
  nodes_[n].parent = parent;
  nodes_[n].begin = begin;
  nodes_[n].end = end;
  if (end - begin <= kLeafTriangles) {
    const int leaf = static_cast<int>(leaf_node_.size());
    leaf_node_.push_back(n);
    nodes_[n].leaf_begin = leaf;
    nodes_[n].leaf_end = leaf + 1;
    for (int p = begin; p < end; ++p) leaf_of_[ids[p]] = leaf;
    return n;
  }
  Box3 bounds;
  for (int p = begin; p < end; ++p) bounds.extend(centroid[ids[p]]);
  int axis = 0;
  bounds.sizes().maxCoeff(&axis);
  const int middle = begin + (end - begin) / 2;
  std::nth_element(ids.begin() + begin, ids.begin() + middle, ids.begin() + end, [&](int s, int t) {
    return centroid[s][axis] != centroid[t][axis] ? centroid[s][axis] < centroid[t][axis] : s < t;
  });
  const int left = build(ids, begin, middle, n, centroid);
  const int right = build(ids, middle, end, n, centroid);
  nodes_[n].child[0] = left;
  nodes_[n].child[1] = right;
  nodes_[n].leaf_begin = nodes_[left].leaf_begin;
  nodes_[n].leaf_end = nodes_[right].leaf_end;
  return n;
}

namespace {

// twins: the triangle across each edge of each triangle (by position in order), -1 for
// none; a triangle on an edge of more than two triangles, or whose neighbour runs the
// edge the same way (inconsistent orientation), is in no disk
void find_twins(const Triangles& triangles, const std::vector<int>& order, std::vector<int>& twin, std::vector<char>& bad) {
  const int count = static_cast<int>(order.size());
  std::vector<int> position(triangles.rows(), -1);
  for (int p = 0; p < count; ++p) position[order[p]] = p;
  std::vector<std::pair<std::uint64_t, int>> half;  // (edge key, 3 p + j)
  half.reserve(3 * order.size());
  for (int p = 0; p < count; ++p) {
    const int t = order[p];
    for (int j = 0; j < 3; ++j) {
      const std::uint64_t a = triangles(t, j), b = triangles(t, (j + 1) % 3);
      half.emplace_back(std::min(a, b) << 32 | std::max(a, b), 3 * p + j);
    }
  }
  std::sort(half.begin(), half.end());
  twin.assign(3 * order.size(), -1);
  bad.assign(count, 0);
  for (size_t i = 0; i < half.size();) {
    size_t j = i;
    while (j < half.size() && half[j].first == half[i].first) ++j;
    if (j - i == 2) {
      const int h0 = half[i].second, h1 = half[i + 1].second;
      const int t0 = order[h0 / 3], t1 = order[h1 / 3];
      if (triangles(t0, h0 % 3) == triangles(t1, h1 % 3)) {  // the same way along the edge
        bad[h0 / 3] = bad[h1 / 3] = 1;
      } else {
        twin[h0] = h1 / 3;
        twin[h1] = h0 / 3;
      }
    } else if (j - i > 2) {
      for (size_t k = i; k < j; ++k) bad[half[k].second / 3] = 1;
    }
    i = j;
  }
}

}  // namespace

// Each node's boundary loop and centre, where the node is a disk: its boundary half-edges
// (those whose twin is not in the node) chain into one loop through distinct vertices, and
// V - E + F = 1
void PatchTree::find_loops(const Triangles& triangles, const Points& x) {
  const int count = static_cast<int>(order_.size());
  const int vertices = static_cast<int>(x.rows());
  std::vector<int> twin;
  std::vector<char> bad;
  find_twins(triangles, order_, twin, bad);
  std::vector<int> bad_before(count + 1, 0);  // prefix counts of bad triangles
  for (int p = 0; p < count; ++p) bad_before[p + 1] = bad_before[p] + bad[p];
  std::vector<int> next(vertices, -1), seen(vertices, -1), on_loop(vertices, -1);
  for (int n = 0; n < static_cast<int>(nodes_.size()); ++n) {
    Node& node = nodes_[n];
    node.loop_begin = node.loop_end = static_cast<int>(loop_.size());
    if (bad_before[node.end] != bad_before[node.begin]) continue;
    bool disk = true;
    int boundary = 0, first = -1, distinct = 0;
    std::vector<int> starts;
    for (int p = node.begin; p < node.end; ++p) {
      const int t = order_[p];
      for (int j = 0; j < 3; ++j) {
        const int k = triangles(t, j);
        if (seen[k] != n) {
          seen[k] = n;
          ++distinct;
        }
        const int across = twin[3 * p + j];
        if (across >= node.begin && across < node.end) continue;
        const int to = triangles(t, (j + 1) % 3);
        if (next[k] >= 0) disk = false;  // two boundary edges leave one vertex: a pinch
        next[k] = to;
        starts.push_back(k);
        if (first < 0) first = k;
        ++boundary;
      }
    }
    const int faces = node.end - node.begin;
    const int edges = (3 * faces + boundary) / 2;
    disk = disk && boundary > 0 && (3 * faces + boundary) % 2 == 0 && distinct - edges + faces == 1;
    if (disk) {
      int k = first, steps = 0;
      do {
        loop_.push_back(k);
        on_loop[k] = n;
        k = next[k];
        ++steps;
      } while (k >= 0 && k != first && steps <= boundary);
      disk = k == first && steps == boundary;
    }
    for (int k : starts) next[k] = -1;
    // the centre: the inner vertex nearest the mean of the node's vertices
    int centre = -1;
    if (disk) {
      Vec3 mean = Vec3::Zero();
      for (int p = node.begin; p < node.end; ++p)
        for (int j = 0; j < 3; ++j) mean += x.row(triangles(order_[p], j)).transpose();
      mean /= 3.0 * faces;
      double best = std::numeric_limits<double>::infinity();
      for (int p = node.begin; p < node.end; ++p) {
        for (int j = 0; j < 3; ++j) {
          const int k = triangles(order_[p], j);
          const double d = (x.row(k).transpose() - mean).squaredNorm();
          if (on_loop[k] != n && (d < best || (d == best && k < centre))) {
            best = d;
            centre = k;
          }
        }
      }
    }
    if (centre < 0) {
      loop_.resize(node.loop_begin);
      continue;
    }
    node.centre = centre;
    node.loop_end = static_cast<int>(loop_.size());
  }
}

void PatchTree::refit_node(int n, const std::vector<Box3>& triangle_boxes) {
  Node& node = nodes_[n];
  node.box.setEmpty();
  if (node.leaf()) {
    for (int p = node.begin; p < node.end; ++p) node.box.extend(triangle_boxes[order_[p]]);
  } else {
    node.box.extend(nodes_[node.child[0]].box).extend(nodes_[node.child[1]].box);
  }
}

void PatchTree::refit(const std::vector<Box3>& triangle_boxes) {
  for (int n = static_cast<int>(nodes_.size()) - 1; n >= 0; --n) refit_node(n, triangle_boxes);  // children first
}

namespace {

// the nodes above the leaves of `changed` triangles, descending (children before parents)
std::vector<int> nodes_above(const PatchTree& tree, const std::vector<int>& changed) {
  std::vector<int> out;
  for (int t : changed) {
    const int leaf = tree.leaf_of(t);
    if (leaf < 0) continue;
    for (int n = tree.leaf_node(leaf); n >= 0; n = tree.nodes()[n].parent) out.push_back(n);
  }
  std::sort(out.begin(), out.end(), std::greater<int>());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

}  // namespace

void PatchTree::refit(const std::vector<Box3>& triangle_boxes, const std::vector<int>& changed) {
  for (int n : nodes_above(*this, changed)) refit_node(n, triangle_boxes);
}

bool PatchTree::flat(int n, const std::vector<std::array<Vec3, 3>>& normal, const std::vector<double>& largest,
                     const Points& x, const Points& v, double dt) const {
  const Node& node = nodes_[n];
  if (node.centre < 0) return false;
  Vec3 axis = Vec3::Zero();
  for (int p = node.begin; p < node.end; ++p) axis += normal[order_[p]][0];
  if (!(axis.squaredNorm() > 0.0) || !axis.allFinite()) return false;
  axis.normalize();
  // 1. every triangle's normal in the cone
  for (int p = node.begin; p < node.end; ++p) {
    const int t = order_[p];
    const auto& b = normal[t];
    if (!(std::min({b[0].dot(axis), b[1].dot(axis), b[2].dot(axis)}) >= kFlat * largest[t])) return false;
  }
  // 2. the boundary a star around the centre: a . ((u - c) x (w - c)) > 0 over the step
  const int c = node.centre;
  const Vec3 xc = x.row(c).transpose(), dc = dt * v.row(c).transpose();
  const int length = node.loop_end - node.loop_begin;
  const auto at = [&](int i, Vec3& position, Vec3& motion) {
    const int k = loop_[node.loop_begin + i % length];
    position = x.row(k).transpose() - xc;
    motion = dt * v.row(k).transpose() - dc;
  };
  double turn = 0.0;
  Vec3 u, du;
  at(0, u, du);
  for (int i = 0; i < length; ++i) {
    Vec3 w, dw;
    at(i + 1, w, dw);
    const Vec3 c0 = u.cross(w), c1 = u.cross(dw) + du.cross(w), c2 = du.cross(dw);
    const Vec3 b[3] = {c0, c0 + 0.5 * c1, c0 + c1 + c2};
    const double least = std::min({b[0].dot(axis), b[1].dot(axis), b[2].dot(axis)});
    const double big = std::sqrt(std::max({b[0].squaredNorm(), b[1].squaredNorm(), b[2].squaredNorm()}));
    if (!(least > kRoom * big)) return false;
    // 3. the turn around c at the start, in the plane across the axis
    turn += std::atan2(axis.dot(c0), u.dot(w) - axis.dot(u) * axis.dot(w));
    u = w;
    du = dw;
  }
  return std::abs(turn - 2.0 * M_PI) < M_PI;
}

}  // namespace simbake
