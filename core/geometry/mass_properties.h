// Volume, centre of mass and inertia tensor of a closed triangle mesh, at unit density.
#pragma once

#include "geometry/mesh.h"

namespace simbake {

struct MassProperties {
  double volume = 0.0;      // (m^3)
  Vec3 center = Vec3::Zero();   // centre of mass (m), in the mesh's frame
  Mat3 inertia = Mat3::Zero();  // inertia tensor about the centre of mass per unit density (m^5)
};

// Exact for any closed, consistently oriented mesh (via the divergence theorem: a sum over
// the signed tetrahedra spanned by the origin and each triangle). Throws if the volume is
// not positive (an open, inside-out or flat mesh).
MassProperties mass_properties(const TriangleMesh& mesh);

// Exact values of the primitives, centred at the origin
MassProperties sphere_mass_properties(double radius);   // I = 2/5 V r^2
MassProperties box_mass_properties(const Vec3& size);   // I_xx = V (y^2 + z^2) / 12, ...

}  // namespace simbake
