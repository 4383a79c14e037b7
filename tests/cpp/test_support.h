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

}  // namespace simbake::test
