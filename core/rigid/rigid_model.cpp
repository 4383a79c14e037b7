// Building the rigid model body by body: a body's description checked, its constant def made
// (principal axes and moments from its unit-density mass properties), its state appended.
#include "rigid/rigid_data.h"
#include "rigid/rigid_model.h"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace simbake {

namespace {

void require(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument(what);
}

bool finite(const Vec3& v) { return v.allFinite(); }

}  // namespace

void check_ground(const GroundDef& ground) {
  require(std::isfinite(ground.height), "ground height must be finite");
  require(ground.friction >= 0.0 && std::isfinite(ground.friction), "ground friction must be >= 0");
  require(ground.restitution >= 0.0 && ground.restitution <= 1.0, "ground restitution must be in [0, 1]");
}

void check_body(const BodyDesc& desc) {
  require(desc.samples.rows() > 0 && desc.samples.allFinite(), "body needs finite surface samples");
  require(desc.kinematic || (desc.mass > 0.0 && std::isfinite(desc.mass)), "body mass must be > 0");
  require(desc.unit_mass.volume > 0.0, "body shape must enclose a positive volume");
  require(finite(desc.origin) && finite(desc.linear_velocity) && finite(desc.angular_velocity) &&
              desc.orientation.coeffs().allFinite() && desc.orientation.norm() > 0.0,
          "body pose and velocities must be finite");
  require(desc.friction >= 0.0 && std::isfinite(desc.friction), "body friction must be >= 0");
  require(desc.restitution >= 0.0 && desc.restitution <= 1.0, "body restitution must be in [0, 1]");
  require(desc.mesh_vertices.allFinite() && (desc.mesh_triangles.rows() == 0 ||
              (desc.mesh_triangles.minCoeff() >= 0 && desc.mesh_triangles.maxCoeff() < desc.mesh_vertices.rows())),
          "body mesh triangles must index its finite vertices");
}

RigidBodyDef make_body_def(const BodyDesc& desc) {
  RigidBodyDef def;
  def.kinematic = desc.kinematic;
  def.friction = desc.friction;
  def.restitution = desc.restitution;
  def.shape = desc.shape;
  def.box = dynamic_cast<const BoxDistance*>(def.shape.get());
  def.sphere = dynamic_cast<const SphereDistance*>(def.shape.get());
  def.samples = desc.samples;
  def.sample_blocks = sample_blocks(def.samples);
  def.sample_groups = sample_groups(def.sample_blocks);
  def.center = desc.unit_mass.center;

  // principal axes of the inertia tensor, as a proper rotation
  Eigen::SelfAdjointEigenSolver<Mat3> eigen(desc.unit_mass.inertia);
  Mat3 axes = eigen.eigenvectors();
  if (axes.determinant() < 0.0) axes.col(2) = -axes.col(2);
  def.mesh_axes = axes;
  if (!desc.kinematic) {
    const double density = desc.mass / desc.unit_mass.volume;  // (kg/m^3)
    def.inverse_mass = 1.0 / desc.mass;
    def.inertia = density * eigen.eigenvalues();
    require(def.inertia.minCoeff() > 0.0, "body inertia must be positive (a flat shape?)");
    // equal moments to round-off (a cube, a sphere): exactly equal, and the rotation exact
    if (def.inertia.maxCoeff() - def.inertia.minCoeff() <= 1e-12 * def.inertia.maxCoeff()) {
      def.inertia.setConstant(def.inertia.mean());
      def.isotropic = true;
      def.mesh_axes = Mat3::Identity();  // (every frame is principal: the mesh's own)
    }
    def.inverse_inertia = def.inertia.cwiseInverse();
  }
  for (Eigen::Index s = 0; s < def.samples.rows(); ++s) {
    const Vec3 p = def.samples.row(s);
    def.bounding_radius = std::max(def.bounding_radius, (p - def.center).norm());
  }
  const Box3 extent = def.shape ? def.shape->bounds()
                                : Box3(def.samples.colwise().minCoeff().transpose(),
                                       def.samples.colwise().maxCoeff().transpose());
  def.thickness = extent.sizes().minCoeff();
  require(def.thickness > 0.0, "body must have a positive extent along every axis");
  return def;
}

void add_body_state(const BodyDesc& desc, const RigidBodyDef& def, RigidData& data) {
  Vec3 x, v = desc.linear_velocity, l = Vec3::Zero(), spin = Vec3::Zero();
  Quat q;
  set_mesh_pose(def, desc.origin, desc.orientation, x, q);
  if (desc.kinematic) {
    spin = desc.angular_velocity;
  } else {
    const Mat3 R = q.toRotationMatrix();
    l = R * def.inertia.asDiagonal() * R.transpose() * desc.angular_velocity;
  }
  data.x.push_back(x);
  data.q.push_back(q);
  data.v.push_back(v);
  data.l.push_back(l);
  data.spin.push_back(spin);
  data.asleep.push_back(0);
  data.rest_time.push_back(0.0);
  data.rest_x.push_back(x);
  data.rest_q.push_back(q);
  data.island.push_back(static_cast<int>(data.island.size()));
}

}  // namespace simbake
