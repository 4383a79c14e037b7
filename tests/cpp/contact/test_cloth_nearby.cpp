// The cloth near a body (contact/cloth_nearby.h): the vertices and edges it lists for a box
// against every vertex and edge tested one by one (the reference: every point, checked here
// with a box test), with vertices moved between the queries and while the edges are listed.
#include <gtest/gtest.h>

#include "contact/cloth_nearby.h"
#include "geometry/mesh.h"

#include <algorithm>
#include <random>
#include <set>

using namespace simbake;

namespace {

// a crumpled sheet: a 24 x 24 grid of triangles, its vertices moved at random by up to
// `jitter` (m), some flung far (a bad step's)
struct Sheet {
  Points x;
  Triangles triangles;
  std::vector<std::array<int, 2>> edges;
};

Sheet crumpled(std::mt19937& random, double jitter) {
  const int n = 24;
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  Sheet s;
  s.x.resize(n * n, 3);
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      s.x.row(j * n + i) << 0.05 * i + jitter * unit(random), jitter * unit(random), 0.05 * j + jitter * unit(random);
    }
  }
  s.x.row(7) << 40.0, -3.0, 2.0;  // flung
  s.triangles.resize(2 * (n - 1) * (n - 1), 3);
  int t = 0;
  for (int j = 0; j + 1 < n; ++j) {
    for (int i = 0; i + 1 < n; ++i) {
      const int a = j * n + i;
      s.triangles.row(t++) << a, a + 1, a + n;
      s.triangles.row(t++) << a + 1, a + n + 1, a + n;
    }
  }
  s.edges = unique_edges(s.triangles);
  return s;
}

bool edge_point_in(const Sheet& s, const std::array<int, 2>& e, const Box3& box) {
  const Vec3 a = s.x.row(e[0]).transpose(), d = Vec3(s.x.row(e[1]).transpose()) - a;
  for (double t : {0.0, 0.25, 0.5, 0.75, 1.0}) {
    if (box.contains(Vec3(a + t * d))) return true;
  }
  return false;
}

}  // namespace

TEST(ClothNearby, ListsEveryVertexAndEdgeInTheBoxInOrder) {
  std::mt19937 random(3);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (int trial = 0; trial < 30; ++trial) {
    Sheet s = crumpled(random, trial % 3 == 0 ? 0.2 : 0.01);
    ClothNearby nearby(static_cast<int>(s.x.rows()), s.edges, s.triangles);
    nearby.begin(s.x);
    for (int body = 0; body < 6; ++body) {
      const Vec3 centre(1.2 * unit(random), 0.2 * unit(random) - 0.1, 1.2 * unit(random));
      const Vec3 half = Vec3::Constant(0.01 + 0.3 * unit(random));
      const Box3 box(centre - half, centre + half);
      // vertices: every one in the box is listed, in increasing order
      const std::vector<int> listed = nearby.vertices(box);
      ASSERT_TRUE(std::is_sorted(listed.begin(), listed.end()));
      ASSERT_EQ(std::adjacent_find(listed.begin(), listed.end()), listed.end());
      for (int k = 0; k < s.x.rows(); ++k) {
        if (box.contains(Vec3(s.x.row(k).transpose()))) {
          EXPECT_TRUE(std::binary_search(listed.begin(), listed.end(), k)) << "trial " << trial << " vertex " << k;
        }
      }
      // edges, while some vertices are moved into the box as they are listed (as contacts
      // move them): every edge with a point in the box when it is reached is listed, in order
      nearby.begin_edges(box);
      std::set<int> seen;
      int last = -1;
      for (int e = 0; e < static_cast<int>(s.edges.size()); ++e) {
        if (edge_point_in(s, s.edges[e], box)) {
          int next;
          while ((next = nearby.next_edge()) >= 0 && next < e) {
            ASSERT_GT(next, last);
            last = next;
            seen.insert(next);
          }
          ASSERT_EQ(next, e) << "trial " << trial << " edge " << e;
          last = next;
          seen.insert(next);
          // move a vertex of a later edge into the box (a contact's push)
          const int k = s.edges[std::min<size_t>(s.edges.size() - 1, e + 40 + random() % 200)][1];
          s.x.row(k) = centre.transpose();
          nearby.moved(k);
        }
      }
      for (int next; (next = nearby.next_edge()) >= 0;) ASSERT_GT(next, last);
    }
  }
}
