// Self-collision's candidates (the method is at the top of self_collision.h): each vertex's
// box over the step in a frame that moves with the cloth, a tree of patches of the surface
// (patch_tree.h) over the cloth's triangles and one over the obstacles', and the pairs of
// items whose boxes meet, found whole or, around the vertices that left their boxes, again.
#include "cloth/self_collision.h"

#include "cloth/self_collision_detail.h"

#include <atomic>
#include <cmath>
#include <numeric>

namespace simbake {

using namespace self_collision_detail;

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

constexpr double kUnmeasured = std::numeric_limits<double>::quiet_NaN();

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

}  // namespace simbake
