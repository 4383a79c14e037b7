// The automatic substep rule.
//
// Bodies. Each body may travel a fraction of its thickness per substep (no tunnelling
// through its own thinnest part), nor more than twice that fraction of the scene's thinnest
// body (no tunnelling through a thin post or plate); its speed over the frame is bounded by
// the current speed of its fastest point plus what gravity adds in one frame. In a world
// where nothing can collide (no ground, no body with a shape) there is nothing to tunnel
// through and the rule does not apply. A jointed body turns at most joint_turn per substep:
// its joints are held at the end of each step by Newton iterations on the rotated frames,
// which converge less surely the further the step turns it (a whipping chain's tip link
// turns hundreds of radians a second); since a whip speeds up within a frame, the world
// checks the turn again after every substep and shortens the rest of the frame's steps
// (World::step_frame). The ceiling
// max_substep applies where bodies interact; with no dynamic body, kinematic bodies need only
// as many steps as their travel (and the cloths) ask for. A bounce is resolved at the step
// whose candidate first enters, so its apex errs by up to the fall over a step: while any
// body may bounce (an awake dynamic body, some restitution above 0) the ceiling is
// bounce_substep; inelastic piles, where speculative and exact box contacts hold at the
// longer max_substep, are not held back by it. Every dynamic body asleep, no kinematic body
// moving and no cloth: nothing can happen before the frame ends, and the bodies take the
// frame in one step (it costs nothing: see World::step_bodies).
//
// Cloths. Their own ceiling, cloth_max_substep; bodies (a keyed collider, say) crossing no
// more of themselves than in a substep; the explicit integrator's speed-of-sound limit; and
// no vertex crossing more than the travel fraction of the thinnest body in a step. A cloth
// that a dynamic body may touch within the frame steps with the bodies, every substep, and
// no longer than cloth_contact_substep: its push on the body is the momentum its vertices
// lose in contact, which is too little, at coarse steps, to hold a heavy body (a ball falls
// through a hammock at long steps). A keyed or moving kinematic body near a cloth travels at most
// half of the cloth's mean edge in a cloth step: its contacts (and, a box or a mesh,
// self-collision's impact zones) carry the vertices it meets along with it, so that an edge
// from a vertex it carries to one it has not reached yet shrinks by what it travels, and the
// strain limiter moves an edge's ends by at most a tenth of an edge a pass
// (cloth/strain_limiting.cpp). Farther, the edges around such a body are dragged past the
// limit, and at a whole edge a step a sheet ploughed by a box is squashed flat in its plane,
// its triangles turned over onto each other, and then crossed. A deforming collider (a
// character's skin) near a cloth moves no vertex more than the cloth's thickness in a cloth
// step: the contacts hold the cloth a thickness off its surface, so a surface that travels
// no farther cannot pass a vertex within the step, where the impact zones could only move it
// with the surface's nearest affine motion (contact/cloth_obstacles.h), which a walking
// figure's legs, swinging against each other, do not have. A walking figure's thigh pushes a
// 5 mm skirt forward at 70 mm a frame: at 5 or 7 cloth steps a frame vertices end inside it
// and it is let through them (cloth_let_in), at 10 none over 5 s; the rule gives 14.
#include "world/schedule.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace simbake {

namespace {

constexpr double kColliderTravel = 0.5;  // of a cloth's mean edge: the most a kinematic body near it moves in a cloth step

// The bodies as the schedule of one frame sees them
class BodySpeeds {
 public:
  BodySpeeds(const RigidModel& model, const RigidData& data, const WorldSettings& settings, double time, double frame_dt,
             const std::vector<const DeformingSurface*>& surfaces)
      : model_(model), data_(data), settings_(settings), surfaces_(surfaces), time_(time), frame_dt_(frame_dt) {}

  // (m), of the bodies something can touch (with a shape); infinite with none
  double thinnest_body() const {
    double thinnest = std::numeric_limits<double>::infinity();
    for (const RigidBodyDef& def : model_.defs) {
      if (def.shape) thinnest = std::min(thinnest, def.thickness);
    }
    return thinnest;
  }

  // the speed (m/s) of body i's fastest point over the frame: its velocities now or, for a
  // keyed body, its track's travel over the frame; gravity's gain over the frame for a dynamic body
  double body_speed(int i) const {
    const RigidBodyDef& def = model_.defs[i];
    double speed = data_.v[i].norm() + body_angular_velocity(model_, data_, i).norm() * def.bounding_radius;
    if (!model_.tracks[i].empty()) {  // a keyed body: how far its track takes it over the frame
      Vec3 o0, o1;
      Quat q0, q1;
      model_.tracks[i].pose_at(time_, o0, q0);
      model_.tracks[i].pose_at(time_ + frame_dt_, o1, q1);
      speed = std::max(speed, ((o1 - o0).norm() + q1.angularDistance(q0) * (def.bounding_radius + def.center.norm())) / frame_dt_);
    }
    if (!def.kinematic) speed += settings_.gravity.norm() * frame_dt_;
    return speed;
  }

  // steps that keep each body's travel short (see the top of this file); with `reach`, those
  // of the kinematic bodies near that box only (as kinematic_speed_near judges near)
  double body_travel_steps(double thinnest, const Box3* reach = nullptr, double reach_speed = 0.0) const {
    double steps = 1.0;
    if (!anything_collides(model_)) return steps;
    for (int i = 0; i < model_.body_count(); ++i) {
      if (data_.asleep[i]) continue;
      const RigidBodyDef& def = model_.defs[i];
      const double speed = body_speed(i);
      if (reach && def.kinematic) {
        const double radius = def.bounding_radius + (speed + reach_speed) * frame_dt_;
        if ((data_.x[i].cwiseMax(reach->min()).cwiseMin(reach->max()) - data_.x[i]).norm() > radius) continue;
      }
      const double limit = settings_.travel_fraction * std::min(def.thickness, 2.0 * thinnest);
      steps = std::max(steps, std::ceil(speed * frame_dt_ / limit));
    }
    return steps;
  }

  // the fastest vertex of a deforming collider that the cloths' box `reach` may meet within
  // the frame (in it, grown by what they travel over the frame) (m/s), 0 if none
  double deforming_speed_near(const Box3& reach, double reach_speed) const {
    double fastest = 0.0;
    const Vec3 grow = Vec3::Constant(reach_speed * frame_dt_);
    for (size_t i = 0; i < surfaces_.size(); ++i) {
      if (surfaces_[i]) fastest = std::max(fastest, surfaces_[i]->fastest_in(Box3(reach.min() - grow, reach.max() + grow)));
    }
    return fastest;
  }

  // the fastest moving kinematic body whose bounding sphere may meet the cloths' box `reach`
  // within the frame (m/s), 0 if none; deforming ones are deforming_speed_near's
  double kinematic_speed_near(const Box3& reach, double reach_speed) const {
    double fastest = 0.0;
    for (int i = 0; i < model_.body_count(); ++i) {
      if (!model_.defs[i].kinematic || !(moving_kinematic(model_, data_, i) || !model_.tracks[i].empty())) continue;
      if (i < static_cast<int>(surfaces_.size()) && surfaces_[i]) continue;
      const double speed = body_speed(i);
      const double radius = model_.defs[i].bounding_radius + (speed + reach_speed) * frame_dt_;
      const Vec3 nearest = data_.x[i].cwiseMax(reach.min()).cwiseMin(reach.max());
      if ((nearest - data_.x[i]).norm() <= radius) fastest = std::max(fastest, speed);
    }
    return fastest;
  }

  // whether an awake dynamic body may touch the cloths' box `reach` within the frame: each
  // one's bounding sphere, grown by what it and the cloth may travel over the frame
  bool dynamic_body_near(const Box3& reach, double reach_speed) const {
    for (int i = 0; i < model_.body_count(); ++i) {
      if (model_.defs[i].kinematic || data_.asleep[i]) continue;
      const Vec3 omega = angular_velocity(model_.defs[i], data_.q[i], data_.l[i]);
      const double speed = data_.v[i].norm() + omega.norm() * model_.defs[i].bounding_radius +
                           settings_.gravity.norm() * frame_dt_;
      const double radius = model_.defs[i].bounding_radius + (speed + reach_speed) * frame_dt_;
      const Vec3 nearest = data_.x[i].cwiseMax(reach.min()).cwiseMin(reach.max());
      if ((nearest - data_.x[i]).norm() <= radius) return true;
    }
    return false;
  }

 private:
  const RigidModel& model_;
  const RigidData& data_;
  const WorldSettings& settings_;
  const std::vector<const DeformingSurface*>& surfaces_;
  double time_, frame_dt_;
};

}  // namespace

bool anything_collides(const RigidModel& model) {
  return model.ground || std::any_of(model.defs.begin(), model.defs.end(),
                                     [](const RigidBodyDef& def) { return def.shape != nullptr; });
}

double jointed_turn_rate(const RigidModel& model, const RigidData& data) {
  double fastest = 0.0;
  for (int i = 0; i < model.body_count(); ++i) {
    if (model.defs[i].kinematic || data.asleep[i] || model.body_joints[i].empty()) continue;
    fastest = std::max(fastest, angular_velocity(model.defs[i], data.q[i], data.l[i]).norm());
  }
  return fastest;
}

namespace {

// The bodies' substeps (before the cloths' say), from their ceiling, travel and joints' turn
double rigid_steps(const RigidModel& model, const RigidData& data, bool cloths, const WorldSettings& settings,
                   double frame_dt, double travel) {
  const double limit = settings.max_substeps;
  bool dynamic = false, awake = false, moving = false, restitution = model.ground && model.ground->restitution > 0.0;
  for (int i = 0; i < model.body_count(); ++i) {
    dynamic = dynamic || !model.defs[i].kinematic;
    awake = awake || (!model.defs[i].kinematic && !data.asleep[i]);
    moving = moving || moving_kinematic(model, data, i) || !model.tracks[i].empty();
    restitution = restitution || model.defs[i].restitution > 0.0;
  }
  const double ceiling = awake && restitution ? std::min(settings.max_substep, settings.bounce_substep) : settings.max_substep;
  const double turn = std::ceil(jointed_turn_rate(model, data) * frame_dt / settings.joint_turn);
  const double steps = std::max({awake || (dynamic && (moving || cloths)) ? std::ceil(frame_dt / ceiling) : 1.0, travel, turn});
  return std::isfinite(steps) ? std::clamp(steps, 1.0, limit) : limit;
}

}  // namespace

FrameSchedule frame_schedule(const RigidModel& model, const RigidData& data, const std::vector<SteppedCloth>& cloths,
                             const WorldSettings& settings, double time, double frame_dt,
                             const std::vector<const DeformingSurface*>& surfaces) {
  const double limit = settings.max_substeps;
  auto bounded = [limit](double steps) { return std::isfinite(steps) ? std::clamp(steps, 1.0, limit) : limit; };
  const BodySpeeds bodies(model, data, settings, time, frame_dt, surfaces);
  const double thinnest = bodies.thinnest_body();
  const double travel = bodies.body_travel_steps(thinnest);
  const double rigid = rigid_steps(model, data, !cloths.empty(), settings, frame_dt, travel);
  if (cloths.empty()) return {static_cast<int>(rigid), 1};

  double steps = std::ceil(frame_dt / settings.cloth_max_substep);
  Box3 reach;                  // the cloths now
  double fastest = 0.0;        // their fastest vertex (m/s)
  double reach_speed = 0.0;    // ... or their thickness over the frame, whichever is more
  double shortest_edge = std::numeric_limits<double>::infinity();  // the least of their mean edges (m)
  double thinnest_cloth = std::numeric_limits<double>::infinity(); // the least of their thicknesses (m)
  for (const SteppedCloth& stepped : cloths) {
    const Cloth& cloth = stepped.cloth;
    if (cloth.integrator() == ClothIntegrator::kExplicit) {
      steps = std::max(steps, std::ceil(frame_dt / cloth.stable_explicit_step()));
    }
    for (int k = 0; k < cloth.vertex_count(); ++k) {
      reach.extend(Vec3(cloth.positions().row(k).transpose()));
      fastest = std::max(fastest, cloth.velocities().row(k).norm());
    }
    reach_speed = std::max({reach_speed, fastest, stepped.contact.thickness() / frame_dt});
    shortest_edge = std::min(shortest_edge, stepped.contact.mean_edge());
    thinnest_cloth = std::min(thinnest_cloth, stepped.contact.thickness());
  }
  // the bodies' travel; with no dynamic body, that of the kinematic bodies near the cloths
  // only (they pass through the ground and each other): a keyed body gone through the cloth
  // at 1 km/s would otherwise hold every frame at hundreds of cloth steps, and at such short
  // steps the cloth's repulsions (0.1 (h - d) / dt) throw its layers about
  bool dynamic = false;
  for (int i = 0; i < model.body_count(); ++i) dynamic = dynamic || !model.defs[i].kinematic;
  steps = std::max(steps, dynamic ? travel : bodies.body_travel_steps(thinnest, &reach, reach_speed));
  const double gravity_speed = settings.gravity.norm() * frame_dt;  // what gravity adds in a frame
  if (model.body_count() > 0) {
    steps = std::max(steps, std::ceil((fastest + gravity_speed) * frame_dt / (settings.travel_fraction * thinnest)));
  }
  const double collider = bodies.kinematic_speed_near(reach, reach_speed);
  if (collider > 0.0 && shortest_edge > 0.0) {
    steps = std::max(steps, std::ceil(collider * frame_dt / (kColliderTravel * shortest_edge)));
  }
  const double skin = bodies.deforming_speed_near(reach, reach_speed);
  if (skin > 0.0 && thinnest_cloth > 0.0) steps = std::max(steps, std::ceil(skin * frame_dt / thinnest_cloth));
  if (bodies.dynamic_body_near(reach, reach_speed + gravity_speed)) {
    steps = std::max({steps, rigid, std::ceil(frame_dt / settings.cloth_contact_substep)});
  }
  const double cloth_steps = bounded(steps);
  // a whole number of substeps per cloth step
  return {static_cast<int>(std::min(cloth_steps * std::ceil(rigid / cloth_steps), limit)), static_cast<int>(cloth_steps)};
}

}  // namespace simbake
