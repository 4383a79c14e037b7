// A cloth's construction and measurements (the stages are integrators.cpp's and
// strain_limiting.cpp's, the element forces cloth_forces.cpp's).
#include "cloth/cloth.h"

#include "cloth/cloth_forces.h"
#include "geometry/mesh.h"

#include <algorithm>

namespace simbake {

namespace {

Vec3 row(const Points& x, int k) { return x.row(k).transpose(); }

}  // namespace

Cloth::Cloth(const ClothDesc& desc)
    : model_(std::make_shared<const ClothModel>(desc)),
      data_{desc.rest, Points::Zero(desc.rest.rows(), 3)},
      solver_(make_solver(*model_, desc.preconditioner)) {}

double Cloth::elastic_energy() const {
  return model_->forces->stretch_energy(data_.x) + model_->forces->bend_energy(data_.x);
}

double Cloth::kinetic_energy() const {
  double e = 0.0;
  for (int k = 0; k < vertex_count(); ++k) e += 0.5 * model_->mass[k] * data_.v.row(k).squaredNorm();
  return e;
}

double Cloth::potential_energy(const Vec3& gravity) const {
  double e = 0.0;
  for (int k = 0; k < vertex_count(); ++k) e -= model_->mass[k] * gravity.dot(row(data_.x, k));
  return e;
}

double Cloth::max_strain() const {
  double strain = -1.0;
  for (const cloth_detail::Edge& e : model_->forces->edges()) {
    strain = std::max(strain, (row(data_.x, e.j) - row(data_.x, e.i)).norm() / e.rest - 1.0);
  }
  return strain;
}

Points Cloth::vertex_normals() const {
  TriangleMesh mesh;
  mesh.vertices = data_.x;
  mesh.triangles = model_->triangles;
  return simbake::vertex_normals(mesh);
}

}  // namespace simbake
