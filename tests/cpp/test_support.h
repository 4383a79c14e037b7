// Small builders shared by the C++ tests.
#pragma once

#include "geometry/mass_properties.h"
#include "geometry/mesh.h"
#include "world/world.h"

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

inline double degrees(double radians) { return radians * 180.0 / M_PI; }

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

}  // namespace simbake::test
