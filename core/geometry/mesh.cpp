#include "geometry/mesh.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <map>
#include <stdexcept>
#include <string>
#include <utility>

namespace simbake {

Points vertex_normals(const TriangleMesh& mesh) {
  Points normals = Points::Zero(mesh.vertices.rows(), 3);
  for (Eigen::Index t = 0; t < mesh.triangles.rows(); ++t) {
    const auto& tri = mesh.triangles.row(t);
    const Vec3 a = mesh.vertices.row(tri[0]);
    const Vec3 b = mesh.vertices.row(tri[1]);
    const Vec3 c = mesh.vertices.row(tri[2]);
    // |(b - a) x (c - a)| is twice the area: weighting by it is area weighting
    const Vec3 face = (b - a).cross(c - a);
    for (int k = 0; k < 3; ++k) normals.row(tri[k]) += face.transpose();
  }
  for (Eigen::Index v = 0; v < normals.rows(); ++v) {
    const double len = normals.row(v).norm();
    if (len > 0.0) {
      normals.row(v) /= len;
    } else {
      normals.row(v) = Vec3::UnitY().transpose();
    }
  }
  return normals;
}

namespace {

// Builds a closed mesh from the six faces of the cube [-1, 1]^3, each split into s x s quads.
// Vertices on shared edges and corners are merged through a key on their integer lattice
// coordinates, so the result is watertight. map_point turns a cube point into the final one.
template <class MapPoint>
TriangleMesh make_cube_lattice(int s, MapPoint map_point) {
  if (s < 1 || s > kMaxSubdivisions) {
    throw std::invalid_argument("subdivisions must be in [1, " + std::to_string(kMaxSubdivisions) + "], got " +
                                std::to_string(s));
  }
  TriangleMesh mesh;
  std::map<std::array<int, 3>, int> index_of;  // lattice coordinate in [0, s]^3 -> vertex
  std::vector<Vec3> vertices;
  std::vector<Eigen::Vector3i> triangles;
  auto vertex = [&](const std::array<int, 3>& key) {
    auto [it, inserted] = index_of.try_emplace(key, static_cast<int>(vertices.size()));
    if (inserted) {
      const Vec3 cube = Vec3(key[0], key[1], key[2]) * (2.0 / s) - Vec3::Ones();
      vertices.push_back(map_point(cube));
    }
    return it->second;
  };
  // each face: fixed axis a at side (0 or 2s), spanned by axes u, v chosen so u x v points out
  for (int a = 0; a < 3; ++a) {
    for (int side = 0; side < 2; ++side) {
      int u = (a + 1) % 3, v = (a + 2) % 3;
      if (side == 0) std::swap(u, v);  // flip winding on the negative face
      for (int i = 0; i < s; ++i) {
        for (int j = 0; j < s; ++j) {
          auto corner = [&](int di, int dj) {
            std::array<int, 3> key{};
            key[a] = side * s;
            key[u] = i + di;
            key[v] = j + dj;
            return vertex(key);
          };
          const int p00 = corner(0, 0), p10 = corner(1, 0), p11 = corner(1, 1), p01 = corner(0, 1);
          triangles.emplace_back(p00, p10, p11);
          triangles.emplace_back(p00, p11, p01);
        }
      }
    }
  }
  mesh.vertices.resize(static_cast<Eigen::Index>(vertices.size()), 3);
  for (std::size_t k = 0; k < vertices.size(); ++k) mesh.vertices.row(k) = vertices[k].transpose();
  mesh.triangles.resize(static_cast<Eigen::Index>(triangles.size()), 3);
  for (std::size_t k = 0; k < triangles.size(); ++k) mesh.triangles.row(k) = triangles[k].transpose();
  return mesh;
}

}  // namespace

TriangleMesh make_sphere_mesh(double radius, int subdivisions) {
  return make_cube_lattice(subdivisions,
                           [radius](const Vec3& c) -> Vec3 { return radius * c.normalized(); });
}

TriangleMesh make_box_mesh(const Vec3& size, int subdivisions) {
  const Vec3 half = 0.5 * size;
  return make_cube_lattice(subdivisions,
                           [half](const Vec3& c) -> Vec3 { return c.cwiseProduct(half); });
}

std::vector<std::array<int, 2>> unique_edges(const Triangles& triangles) {
  std::vector<std::array<int, 2>> edges;
  edges.reserve(static_cast<std::size_t>(triangles.rows()) * 3);
  for (Eigen::Index t = 0; t < triangles.rows(); ++t) {
    for (int k = 0; k < 3; ++k) {
      const int a = triangles(t, k), b = triangles(t, (k + 1) % 3);
      edges.push_back({std::min(a, b), std::max(a, b)});
    }
  }
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  return edges;
}

Points surface_samples(const TriangleMesh& mesh, double max_spacing) {
  if (!(max_spacing > 0.0)) throw std::invalid_argument("sample spacing must be > 0");
  std::vector<Vec3> extra;
  for (const auto& [a, b] : unique_edges(mesh.triangles)) {
    const Vec3 pa = mesh.vertices.row(a), pb = mesh.vertices.row(b);
    const int pieces = static_cast<int>(std::ceil((pb - pa).norm() / max_spacing));
    for (int k = 1; k < pieces; ++k) extra.push_back(pa + (pb - pa) * (double(k) / pieces));
  }
  Points samples(mesh.vertices.rows() + static_cast<Eigen::Index>(extra.size()), 3);
  samples.topRows(mesh.vertices.rows()) = mesh.vertices;
  for (std::size_t k = 0; k < extra.size(); ++k) samples.row(mesh.vertices.rows() + k) = extra[k].transpose();
  return samples;
}

bool is_closed(const TriangleMesh& mesh) {
  // directed edge (a, b) -> count; closed and consistently oriented iff each appears once
  // and its reverse appears once
  std::map<std::pair<int, int>, int> directed;
  for (Eigen::Index t = 0; t < mesh.triangles.rows(); ++t) {
    for (int k = 0; k < 3; ++k) {
      const int a = mesh.triangles(t, k), b = mesh.triangles(t, (k + 1) % 3);
      if (++directed[{a, b}] > 1) return false;
    }
  }
  for (const auto& [edge, count] : directed) {
    if (directed.find({edge.second, edge.first}) == directed.end()) return false;
  }
  return !directed.empty();
}

}  // namespace simbake
