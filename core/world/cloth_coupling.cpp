#include "world/cloth_coupling.h"

#include "rigid/sleeping.h"

namespace simbake {

void record_start_poses(const RigidModel& model, const RigidData& data, ClothCoupling& coupling, double time) {
  coupling.start_time = time;
  std::vector<Pose>& start_poses = coupling.start_poses;
  start_poses.resize(model.body_count());
  for (int b = 0; b < model.body_count(); ++b) start_poses[b] = body_mesh_pose(model, data, b);
}

void describe_bodies(const RigidModel& model, const RigidData& data, ClothCoupling& coupling, double time) {
  const std::vector<Pose>& start_poses = coupling.start_poses;
  ContactBodies& out = coupling.bodies;
  out.clear();
  for (int b = 0; b < model.body_count(); ++b) {
    const RigidBodyDef& def = model.defs[b];
    ContactBody body;
    body.shape = def.shape.get();
    body.mesh = &model.meshes[b];
    body.pose = body_mesh_pose(model, data, b);
    body.start_pose = b < static_cast<int>(start_poses.size()) ? start_poses[b] : body.pose;
    body.center = data.x[b];
    body.orientation = data.q[b];
    body.bounding_radius = def.bounding_radius;
    body.friction = def.friction;
    body.inverse_mass = def.inverse_mass;
    body.inverse_inertia = def.inverse_inertia;
    body.isotropic = def.isotropic;
    body.spin = data.spin[b];
    body.kinematic = def.kinematic;
    body.still = def.kinematic && !moving_kinematic(model, data, b);
    body.island = data.island[b];
    if (b < static_cast<int>(coupling.surfaces.size()) && coupling.surfaces[b]) {
      const DeformingSurface& surface = *coupling.surfaces[b];
      body.surface = &surface;
      body.surface_start = surface.blend(coupling.start_time);
      body.surface_end = surface.blend(time);
      body.still = false;
    }
    out.add(body, data.v[b], data.l[b], data.asleep[b] != 0);
  }
  if (model.ground) out.set_ground(ContactGround{model.ground->height, model.ground->friction});
}

void apply_contact_results(const ContactBodies& bodies, const RigidModel& model, RigidData& data) {
  // (the contacts' own arithmetic, in their order: the bodies end as the contacts' buffer did)
  for (const BodyImpulse& i : bodies.impulses()) {
    data.v[i.body] += model.defs[i.body].inverse_mass * i.impulse;
    data.l[i.body] += (i.point - data.x[i.body]).cross(i.impulse);
    if (!i.angular.isZero(0.0)) data.l[i.body] += i.angular;
  }
  for (int b : bodies.woken()) wake_island(model, data, b);
  for (const BodyDisplacement& d : bodies.displacements()) {
    data.x[d.body] += d.dt * d.velocity;
    data.q[d.body] = prescribed_rotation(data.q[d.body], d.omega, d.dt);
  }
}

}  // namespace simbake
