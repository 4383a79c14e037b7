// The self-collision broad phase's patch tree (cloth/patch_tree.h): its patches' boundaries
// against a count of the grid's edges, and the flatness test against brute force.
#include <gtest/gtest.h>

#include "cloth/patch_tree.h"
#include "test_support.h"

#include <map>
#include <random>
#include <set>

using namespace simbake;
using namespace simbake::test;

namespace {

std::vector<int> all_triangles(const Triangles& t) {
  std::vector<int> ids(t.rows());
  std::iota(ids.begin(), ids.end(), 0);
  return ids;
}

// the edges used by one triangle only among `triangles` (the patch's boundary)
int boundary_edges(const Triangles& t, const std::vector<int>& triangles) {
  std::map<std::pair<int, int>, int> uses;
  for (int i : triangles) {
    for (int j = 0; j < 3; ++j) {
      const int a = t(i, j), b = t(i, (j + 1) % 3);
      ++uses[{std::min(a, b), std::max(a, b)}];
    }
  }
  int count = 0;
  for (const auto& [edge, n] : uses) count += n == 1;
  return count;
}


}  // namespace

TEST(PatchTree, NodesOfAGridAreDisksWithTheirWholeBoundary) {
  // a 17 x 17 grid: the root's loop is the grid's edge (64 vertices); every node that is a
  // disk has a loop as long as its boundary edges, counted here, and a centre off it; and the
  // median splits of a grid leave nearly every node a disk
  const ClothDesc d = grid_cloth(17, 17, 1.0, 1.0);
  const PatchTree tree(d.triangles, all_triangles(d.triangles), d.rest);
  const auto& nodes = tree.nodes();
  ASSERT_FALSE(nodes.empty());
  EXPECT_EQ(nodes[0].loop_end - nodes[0].loop_begin, 64);
  int disks = 0, large = 0;
  for (const auto& node : nodes) {
    const std::vector<int> triangles(tree.order().begin() + node.begin, tree.order().begin() + node.end);
    EXPECT_LE(node.end - node.begin, node.leaf() ? 8 : 1 << 30);
    if (node.end - node.begin >= 16) ++large;
    if (node.centre < 0) continue;
    if (node.end - node.begin >= 16) ++disks;
    EXPECT_EQ(node.loop_end - node.loop_begin, boundary_edges(d.triangles, triangles));
    const std::set<int> loop(tree.loop().begin() + node.loop_begin, tree.loop().begin() + node.loop_end);
    EXPECT_EQ(static_cast<int>(loop.size()), node.loop_end - node.loop_begin);  // no vertex twice
    EXPECT_EQ(loop.count(node.centre), 0u);
  }
  std::printf("  %d of %d nodes of 16 triangles or more are disks\n", disks, large);
  EXPECT_GE(disks, large * 9 / 10);
}

TEST(PatchTree, FlatPatchesNeverMeetThemselves) {
  // patch_tree.h's argument, checked by brute force: a 7 x 7 grid bent into a gentle height
  // field, then moved by a smooth random field (a turn, a bend) plus noise of up to an edge
  // length; in every node the test calls flat, no point meets a triangle of the node it is not
  // a vertex of and no edge crosses another it shares no vertex with, over the move. Nodes
  // that are not flat must have such pairs meet, so that the check can fail.
  const ClothDesc d = grid_cloth(7, 7, 6.0, 6.0);  // edges 1 long
  const Triangles& t = d.triangles;
  const std::vector<std::array<int, 2>> edges = unique_edges(t);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  int flat_nodes = 0, other_nodes = 0, met_flat = 0, met_other = 0;
  for (int trial = 0; trial < 200; ++trial) {
    const double noise = 1.0 * trial / 200.0;
    const double bend = 0.6 * unit(rng), turn = 1.5 * unit(rng);
    Points x0 = d.rest, x1(d.rest.rows(), 3);
    for (Eigen::Index k = 0; k < x0.rows(); ++k) {
      const double px = d.rest(k, 0) - 3.0, pz = d.rest(k, 2) - 3.0;
      x0(k, 1) = 0.3 * std::sin(px) * std::cos(0.7 * pz);
      x0(k, 0) += 0.15 * unit(rng);
      x0(k, 2) += 0.15 * unit(rng);
      // turned about y, bent along x, and noise
      const double c = std::cos(turn), s = std::sin(turn);
      x1(k, 0) = 3.0 + c * px - s * pz;
      x1(k, 2) = 3.0 + s * px + c * pz;
      x1(k, 1) = x0(k, 1) + bend * px * px;
      for (int a = 0; a < 3; ++a) x1(k, a) += noise * unit(rng);
    }
    const Points v = x1 - x0;
    // each triangle's normal over the move, by its Bernstein coefficients (written again here)
    std::vector<std::array<Vec3, 3>> normal(t.rows());
    std::vector<double> largest(t.rows());
    for (Eigen::Index i = 0; i < t.rows(); ++i) {
      const Vec3 a0 = x0.row(t(i, 0)).transpose(), e1 = x0.row(t(i, 1)).transpose() - a0, e2 = x0.row(t(i, 2)).transpose() - a0;
      const Vec3 da = v.row(t(i, 0)).transpose();
      const Vec3 d1 = v.row(t(i, 1)).transpose() - da, d2 = v.row(t(i, 2)).transpose() - da;
      const Vec3 c0 = e1.cross(e2), c1 = e1.cross(d2) + d1.cross(e2), c2 = d1.cross(d2);
      normal[i] = {c0, c0 + 0.5 * c1, c0 + c1 + c2};
      largest[i] = std::max({normal[i][0].norm(), normal[i][1].norm(), normal[i][2].norm()});
    }
    const PatchTree tree(t, all_triangles(t), x0);
    for (int n = 0; n < static_cast<int>(tree.nodes().size()); ++n) {
      const auto& node = tree.nodes()[n];
      const bool flat = tree.flat(n, normal, largest, x0, v, 1.0);
      std::set<int> vertices, node_edges;
      for (int p = node.begin; p < node.end; ++p) {
        for (int j = 0; j < 3; ++j) vertices.insert(t(tree.order()[p], j));
      }
      for (size_t e = 0; e < edges.size(); ++e) {
        for (int p = node.begin; p < node.end; ++p) {
          const int i = tree.order()[p];
          const auto on = [&](int k) { return t(i, 0) == k || t(i, 1) == k || t(i, 2) == k; };
          if (on(edges[e][0]) && on(edges[e][1])) node_edges.insert(static_cast<int>(e));
        }
      }
      int met = 0;
      for (int p = node.begin; p < node.end; ++p) {
        const int i = tree.order()[p];
        for (int k : vertices) {
          if (k != t(i, 0) && k != t(i, 1) && k != t(i, 2)) met += meet(true, {k, t(i, 0), t(i, 1), t(i, 2)}, x0, x1);
        }
      }
      for (int e : node_edges) {
        for (int f : node_edges) {
          const auto [a, b] = edges[e];
          const auto [c, g] = edges[f];
          if (f <= e || a == c || a == g || b == c || b == g) continue;
          met += meet(false, {a, b, c, g}, x0, x1);
        }
      }
      (flat ? flat_nodes : other_nodes) += 1;
      (flat ? met_flat : met_other) += met;
    }
  }
  std::printf("  %d flat nodes (pairs met: %d), %d others (met: %d)\n", flat_nodes, met_flat, other_nodes, met_other);
  EXPECT_GT(flat_nodes, 200);
  EXPECT_EQ(met_flat, 0);
  EXPECT_GT(met_other, 100);
}
