// Small builders shared by the C++ tests.
#pragma once

#include "geometry/mass_properties.h"
#include "geometry/mesh.h"
#include "world/world.h"

#include <array>
#include <cmath>

namespace simbake::test {

inline BodyDesc sphere_body(double radius, double mass, const Vec3& origin, int subdivisions = 8) {
  BodyDesc d;
  d.shape = std::make_shared<SphereDistance>(radius);
  d.samples = make_sphere_mesh(radius, subdivisions).vertices;
  d.unit_mass = sphere_mass_properties(radius);
  d.mass = mass;
  d.origin = origin;
  return d;
}

inline BodyDesc box_body(const Vec3& size, double mass, const Vec3& origin, int subdivisions = 1) {
  BodyDesc d;
  d.shape = std::make_shared<BoxDistance>(size);
  d.samples = make_box_mesh(size, subdivisions).vertices;
  d.unit_mass = box_mass_properties(size);
  d.mass = mass;
  d.origin = origin;
  return d;
}

// A kinematic body to deform (World::set_deforming_frame): a sphere mesh's `vertices` (world
// coordinates, its mesh pose the identity) and `triangles`, the level set of a sphere of
// `radius` at the origin
inline BodyDesc deforming_sphere_body(const Points& vertices, const Triangles& triangles, double radius) {
  BodyDesc d;
  d.shape = std::make_shared<SphereDistance>(radius);
  d.samples = vertices;
  d.mesh_vertices = vertices;
  d.mesh_triangles = triangles;
  d.unit_mass = sphere_mass_properties(radius);
  d.kinematic = true;
  return d;
}

inline double degrees(double radians) { return radians * 180.0 / M_PI; }

// A cloth's description with its contact settings: friction against bodies and the ground,
// the thickness it keeps from them (m), and whether it collides with itself
inline ClothDesc with_contacts(ClothDesc desc, double friction, double thickness, bool self_collision = true) {
  desc.friction = friction;
  desc.thickness = thickness;
  desc.self_collision = self_collision;
  return desc;
}

// A flat grid cloth of nx x nz vertices spanning size_x x size_z in the XZ plane from the
// corner `origin`, vertex (i, j) at index j * nx + i; each cell split along (i, j)-(i+1, j+1)
// as the pipeline's grid_mesh does
inline ClothDesc grid_cloth(int nx, int nz, double size_x, double size_z, const Vec3& origin = Vec3::Zero()) {
  ClothDesc d;
  d.rest.resize(nx * nz, 3);
  for (int j = 0; j < nz; ++j) {
    for (int i = 0; i < nx; ++i) {
      d.rest.row(j * nx + i) << origin.x() + size_x * i / (nx - 1), origin.y(), origin.z() + size_z * j / (nz - 1);
    }
  }
  d.triangles.resize(2 * (nx - 1) * (nz - 1), 3);
  int t = 0;
  for (int j = 0; j + 1 < nz; ++j) {
    for (int i = 0; i + 1 < nx; ++i) {
      const int p00 = j * nx + i, p10 = p00 + 1, p01 = p00 + nx, p11 = p01 + 1;
      d.triangles.row(t++) << p00, p01, p11;
      d.triangles.row(t++) << p00, p11, p10;
    }
  }
  return d;
}

// brute force over the step: does the point p meet triangle abc, or edge a b cross edge c d,
// at some s in [0, 1] (positions x0 + s (x1 - x0))? The signed volume of the four points is
// sampled finely; at each sign change the root is bisected and the two features checked for
// touching there. Written apart from the solver's cubic.
inline bool meet(bool point, const std::array<int, 4>& ids, const Points& x0, const Points& x1) {
  const auto at = [&](double s, int k) { return Vec3(x0.row(ids[k]).transpose() + s * (x1.row(ids[k]) - x0.row(ids[k])).transpose()); };
  const auto volume = [&](double s) {
    const Vec3 a = at(s, 0), b = at(s, 1), c = at(s, 2), d = at(s, 3);
    return point ? (c - b).cross(d - b).dot(a - b) : (b - a).cross(d - c).dot(c - a);
  };
  const auto touching = [&](double s) {
    const Vec3 a = at(s, 0), b = at(s, 1), c = at(s, 2), d = at(s, 3);
    if (point) {  // a inside triangle b c d (barycentric weights of its projection)
      const Vec3 n = (c - b).cross(d - b);
      const double area = n.squaredNorm();
      if (area == 0.0) return false;
      const double u = (c - a).cross(d - a).dot(n) / area, v = (d - a).cross(b - a).dot(n) / area;
      return u >= -1e-9 && v >= -1e-9 && 1.0 - u - v >= -1e-9;
    }
    // the closest points of the two segments, both inside, at the same place
    const Vec3 e = b - a, f = d - c, r = a - c;
    const double ee = e.squaredNorm(), ff = f.squaredNorm(), ef = e.dot(f), denominator = ee * ff - ef * ef;
    if (denominator <= 1e-14 * ee * ff) return false;
    const double s1 = (ef * f.dot(r) - ff * e.dot(r)) / denominator, t1 = (ee * f.dot(r) - ef * e.dot(r)) / denominator;
    return s1 >= -1e-9 && s1 <= 1 + 1e-9 && t1 >= -1e-9 && t1 <= 1 + 1e-9 && (a + s1 * e - c - t1 * f).norm() < 1e-6;
  };
  Box3 first, second;  // the two sides over the step: apart, they cannot meet
  for (int k = 0; k < 4; ++k) {
    Box3& box = k < (point ? 1 : 2) ? first : second;
    box.extend(Vec3(x0.row(ids[k]).transpose())).extend(Vec3(x1.row(ids[k]).transpose()));
  }
  if (!first.intersects(second)) return false;
  constexpr int kSamples = 200;
  double previous = volume(0.0);
  for (int i = 1; i <= kSamples; ++i) {
    double lo = (i - 1.0) / kSamples, hi = static_cast<double>(i) / kSamples;
    const double next = volume(hi);
    if ((previous < 0.0) != (next < 0.0)) {
      double f_lo = previous;
      for (int k = 0; k < 60; ++k) {
        const double mid = 0.5 * (lo + hi), f_mid = volume(mid);
        if ((f_lo < 0.0) == (f_mid < 0.0)) {
          lo = mid;
          f_lo = f_mid;
        } else {
          hi = mid;
        }
      }
      if (touching(0.5 * (lo + hi))) return true;
    }
    previous = next;
  }
  return false;
}

}  // namespace simbake::test
