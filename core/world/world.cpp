// World construction, the frame loop, the automatic substep rule and statistics.
// The stages themselves are in rigid_stages.cpp.
#include "world/world.h"

#include "rigid/box_contact.h"
#include "world/scoped_timer.h"

#include <Eigen/Eigenvalues>
#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace simbake {

namespace {

constexpr double kColliderTravel = 0.5;  // of a cloth's mean edge: the most a kinematic body near it moves in a cloth step

void require(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument(what);
}

bool finite(const Vec3& v) { return v.allFinite(); }

}  // namespace

World::World(const WorldSettings& settings) : settings_(settings) {
  require(settings.gravity.allFinite(), "gravity must be finite");
  require(settings.collision_sweeps >= 0 && settings.contact_sweeps >= 0, "sweeps must be >= 0");
  require(settings.max_substep > 0.0 && settings.travel_fraction > 0.0 && settings.cloth_contact_substep > 0.0 &&
              settings.bounce_substep > 0.0,
          "substep limits must be > 0");
  require(settings.max_substeps >= 1, "max_substeps must be >= 1");
  require(settings.threads >= 0, "threads must be >= 0");
}

void World::set_ground(const GroundDef& ground) {
  require(std::isfinite(ground.height), "ground height must be finite");
  require(ground.friction >= 0.0 && std::isfinite(ground.friction), "ground friction must be >= 0");
  require(ground.restitution >= 0.0 && ground.restitution <= 1.0, "ground restitution must be in [0, 1]");
  ground_ = ground;
}

int World::add_body(const BodyDesc& desc) {
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

  RigidBodyDef def;
  def.kinematic = desc.kinematic;
  def.friction = desc.friction;
  def.restitution = desc.restitution;
  def.shape = desc.shape;
  def.box = dynamic_cast<const BoxDistance*>(def.shape.get());
  def.samples = desc.samples;
  def.sample_blocks = sample_blocks(def.samples);
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

  RigidBodyState state;
  set_mesh_pose(def, desc.origin, desc.orientation, state);
  state.v = desc.linear_velocity;
  Vec3 spin = Vec3::Zero();
  if (desc.kinematic) {
    spin = desc.angular_velocity;
  } else {
    const Mat3 R = state.q.toRotationMatrix();
    state.l = R * def.inertia.asDiagonal() * R.transpose() * desc.angular_velocity;
  }
  defs_.push_back(std::move(def));
  states_.push_back(state);
  spin_.push_back(spin);
  tracks_.emplace_back();
  candidates_.push_back(state);
  candidate_poses_.push_back(mesh_pose(defs_.back(), state));
  omega_.push_back(Vec3::Zero());
  inverse_inertia_.push_back(Mat3::Zero());
  stale_.push_back(0);
  version_.push_back(0);
  frozen_.push_back(0);
  level_.push_back(-1);
  boxes_.emplace_back();
  asleep_.push_back(0);
  rest_time_.push_back(0.0);
  rest_pose_.push_back(state);
  island_.push_back(body_count() - 1);
  body_meshes_.push_back({desc.mesh_vertices, desc.mesh_triangles});
  return body_count() - 1;
}

void World::set_kinematic_track(int i, KinematicTrack track) {
  require(i >= 0 && i < body_count() && defs_[i].kinematic, "only kinematic bodies follow keys");
  tracks_[i] = std::move(track);
  move_kinematic_bodies(0.0);
}

// Keyed bodies sit on their track at the step's start and move at the constant velocity and
// spin that reach the track's pose at the step's end exactly (update_positions moves them)
void World::move_kinematic_bodies(double dt) {
  for (int i = 0; i < body_count(); ++i) {
    if (tracks_[i].empty()) continue;
    Vec3 origin, origin_next;
    Quat orientation, orientation_next;
    tracks_[i].pose_at(time_, origin, orientation);
    set_mesh_pose(defs_[i], origin, orientation, states_[i]);
    if (dt <= 0.0) {
      states_[i].v = Vec3::Zero();
      spin_[i] = Vec3::Zero();
      continue;
    }
    tracks_[i].pose_at(time_ + dt, origin_next, orientation_next);
    RigidBodyState next;
    set_mesh_pose(defs_[i], origin_next, orientation_next, next);
    states_[i].v = (next.x - states_[i].x) / dt;
    spin_[i] = rotation_vector_from_quat(next.q * states_[i].q.conjugate()) / dt;
  }
}

int World::automatic_substeps(double frame_dt) const { return frame_schedule(frame_dt).substeps; }

int World::automatic_cloth_steps(double frame_dt) const { return frame_schedule(frame_dt).cloth_steps; }

World::FrameSchedule World::frame_schedule(double frame_dt) const {
  const double limit = settings_.max_substeps;
  auto bounded = [limit](double steps) { return std::isfinite(steps) ? std::clamp(steps, 1.0, limit) : limit; };
  const double thinnest = thinnest_body();
  const double travel = body_travel_steps(frame_dt, thinnest);
  // bodies: the ceiling applies where bodies interact; with no dynamic body, kinematic bodies
  // need only as many steps as their travel (and the cloths) ask for. A bounce is resolved at
  // the step whose candidate first enters, so its apex errs by up to the fall over a step
  // (benchmarks/rigid_bounce.py: the worst of 8 drops 16% off at 1/240 s, 28% at 1/120 s):
  // while any body may bounce (an awake dynamic body, some restitution above 0) the ceiling
  // is bounce_substep; inelastic piles, where speculative and exact box contacts hold at the
  // longer max_substep, are not held back by it
  // Every dynamic body asleep, no kinematic body moving and no cloth: nothing can happen before
  // the frame ends, and the bodies take the frame in one step (it costs nothing: see step_bodies)
  bool dynamic = false, awake = false, moving = false, restitution = ground_ && ground_->restitution > 0.0;
  for (int i = 0; i < body_count(); ++i) {
    dynamic = dynamic || !defs_[i].kinematic;
    awake = awake || (!defs_[i].kinematic && !asleep_[i]);
    moving = moving || moving_kinematic(i) || !tracks_[i].empty();
    restitution = restitution || defs_[i].restitution > 0.0;
  }
  const double ceiling = awake && restitution ? std::min(settings_.max_substep, settings_.bounce_substep) : settings_.max_substep;
  const double rigid = bounded(std::max(awake || (dynamic && (moving || !cloths_.empty())) ? std::ceil(frame_dt / ceiling) : 1.0, travel));
  if (cloths_.empty()) return {static_cast<int>(rigid), 1};

  // cloths: their own ceiling; bodies (a keyed collider, say) crossing no more of themselves
  // than in a substep; the explicit integrator's speed-of-sound limit; and no vertex crossing
  // more than the travel fraction of the thinnest body in a step. A cloth that a dynamic
  // body may touch within the frame steps with the bodies, every substep, and no longer than
  // cloth_contact_substep (1/240 s, the bodies' ceiling before their own became 1/120 s): its
  // push on the body is the momentum its vertices lose in contact, which is too little, at
  // coarse steps, to hold a heavy body (a ball falls through a hammock at 1/60 s)
  double steps = std::ceil(frame_dt / settings_.cloth_max_substep);
  Box3 reach;                  // the cloths now
  double fastest = 0.0;        // their fastest vertex (m/s)
  double reach_speed = 0.0;    // ... or their thickness over the frame, whichever is more
  double shortest_edge = std::numeric_limits<double>::infinity();  // the least of their mean edges (m)
  for (size_t c = 0; c < cloths_.size(); ++c) {
    const Cloth& cloth = cloths_[c];
    if (cloth.integrator() == ClothIntegrator::kExplicit) {
      steps = std::max(steps, std::ceil(frame_dt / cloth.stable_explicit_step()));
    }
    for (int k = 0; k < cloth.vertex_count(); ++k) {
      reach.extend(Vec3(cloth.positions().row(k).transpose()));
      fastest = std::max(fastest, cloth.velocities().row(k).norm());
    }
    reach_speed = std::max({reach_speed, fastest, cloth_contacts_[c].thickness() / frame_dt});
    shortest_edge = std::min(shortest_edge, cloth_contacts_[c].mean_edge());
  }
  // the bodies' travel; with no dynamic body, that of the kinematic bodies near the cloths only
  // (they pass through the ground and each other): counted wherever it was, a keyed body at
  // 1 km/s held every frame at 695 cloth steps long after it had gone through the cloth, and
  // at such steps the cloth's repulsions (0.1 (h - d) / dt) threw its layers about at 8 m/s
  steps = std::max(steps, dynamic ? travel : body_travel_steps(frame_dt, thinnest, &reach, reach_speed));
  const double gravity_speed = settings_.gravity.norm() * frame_dt;  // what gravity adds in a frame
  if (body_count() > 0) {
    steps = std::max(steps, std::ceil((fastest + gravity_speed) * frame_dt / (settings_.travel_fraction * thinnest)));
  }
  // a keyed or moving kinematic body near a cloth travels at most half of its mean edge in a
  // cloth step: its contacts (and, a box or a mesh, self-collision's impact zones) carry the
  // vertices it meets along with it, so that an edge from a vertex it carries to one it has not
  // reached yet shrinks by what it travels, and the strain limiter moves an edge's ends by at
  // most a tenth of an edge a pass (cloth.cpp). Farther, the edges around it were dragged
  // past the limit (the stress run's cape on a box spinning at 30 rad/s, 0.11 m a step at 5
  // steps a frame against 0.044 m edges: 254% at a frame's end), and at a whole edge a step
  // the sheet a box ploughs at 10 m/s was squashed flat in its plane, its triangles turned
  // over onto each other, and then crossed
  const double collider = kinematic_speed_near(reach, reach_speed, frame_dt);
  if (collider > 0.0 && shortest_edge > 0.0) {
    steps = std::max(steps, std::ceil(collider * frame_dt / (kColliderTravel * shortest_edge)));
  }
  if (dynamic_body_near(reach, reach_speed + gravity_speed, frame_dt)) {
    steps = std::max({steps, rigid, std::ceil(frame_dt / settings_.cloth_contact_substep)});
  }
  const double cloth_steps = bounded(steps);
  // a whole number of substeps per cloth step
  return {static_cast<int>(std::min(cloth_steps * std::ceil(rigid / cloth_steps), limit)), static_cast<int>(cloth_steps)};
}

bool World::dynamic_body_near(const Box3& reach, double reach_speed, double frame_dt) const {
  // each awake dynamic body's bounding sphere, grown by what it and the cloth may travel over
  // the frame, against the cloths' box
  for (int i = 0; i < body_count(); ++i) {
    if (defs_[i].kinematic || asleep_[i]) continue;
    const Vec3 omega = angular_velocity(defs_[i], states_[i]);
    const double speed = states_[i].v.norm() + omega.norm() * defs_[i].bounding_radius + settings_.gravity.norm() * frame_dt;
    const double radius = defs_[i].bounding_radius + (speed + reach_speed) * frame_dt;
    const Vec3 nearest = states_[i].x.cwiseMax(reach.min()).cwiseMin(reach.max());
    if ((nearest - states_[i].x).norm() <= radius) return true;
  }
  return false;
}

double World::thinnest_body() const {
  double thinnest = std::numeric_limits<double>::infinity();
  for (const RigidBodyDef& def : defs_) thinnest = std::min(thinnest, def.thickness);
  return thinnest;
}

double World::body_speed(int i, double frame_dt) const {
  const RigidBodyDef& def = defs_[i];
  double speed = states_[i].v.norm() + body_angular_velocity(i).norm() * def.bounding_radius;
  if (!tracks_[i].empty()) {  // a keyed body: how far its track takes it over the frame
    Vec3 o0, o1;
    Quat q0, q1;
    tracks_[i].pose_at(time_, o0, q0);
    tracks_[i].pose_at(time_ + frame_dt, o1, q1);
    speed = std::max(speed, ((o1 - o0).norm() + q1.angularDistance(q0) * (def.bounding_radius + def.center.norm())) / frame_dt);
  }
  if (!def.kinematic) speed += settings_.gravity.norm() * frame_dt;
  return speed;
}

double World::kinematic_speed_near(const Box3& reach, double reach_speed, double frame_dt) const {
  double fastest = 0.0;
  for (int i = 0; i < body_count(); ++i) {
    if (!defs_[i].kinematic || !(moving_kinematic(i) || !tracks_[i].empty())) continue;
    const double speed = body_speed(i, frame_dt);
    const double radius = defs_[i].bounding_radius + (speed + reach_speed) * frame_dt;
    const Vec3 nearest = states_[i].x.cwiseMax(reach.min()).cwiseMin(reach.max());
    if ((nearest - states_[i].x).norm() <= radius) fastest = std::max(fastest, speed);
  }
  return fastest;
}

double World::body_travel_steps(double frame_dt, double thinnest, const Box3* reach, double reach_speed) const {
  // Each body may travel a fraction of its thickness per substep (no tunnelling through its
  // own thinnest part), nor more than twice that fraction of the scene's thinnest body (no
  // tunnelling through a thin post or plate); its speed over the frame is bounded by the
  // current speed of its fastest point plus what gravity adds in one frame.
  double steps = 1.0;
  for (int i = 0; i < body_count(); ++i) {
    if (asleep_[i]) continue;
    const RigidBodyDef& def = defs_[i];
    const double speed = body_speed(i, frame_dt);
    if (reach && def.kinematic) {  // (as kinematic_speed_near judges near)
      const double radius = def.bounding_radius + (speed + reach_speed) * frame_dt;
      if ((states_[i].x.cwiseMax(reach->min()).cwiseMin(reach->max()) - states_[i].x).norm() > radius) continue;
    }
    const double limit = settings_.travel_fraction * std::min(def.thickness, 2.0 * thinnest);
    steps = std::max(steps, std::ceil(speed * frame_dt / limit));
  }
  return steps;
}

int World::step_frame(double frame_dt, int substeps, const std::function<bool()>& stop) {
  require(frame_dt > 0.0 && std::isfinite(frame_dt), "frame_dt must be > 0");
  // the cloths step once every `group` substeps, over the group's time (a fixed substep
  // count steps them every substep)
  const FrameSchedule schedule = substeps > 0 ? FrameSchedule{substeps, substeps} : frame_schedule(frame_dt);
  const int n = std::min(schedule.substeps, settings_.max_substeps);
  const double dt = frame_dt / n;
  const int cloth_steps = std::min(schedule.cloth_steps, n);
  const int group = n % cloth_steps == 0 ? n / cloth_steps : 1;
  tbb::task_arena arena(settings_.threads > 0 ? settings_.threads : tbb::task_arena::automatic);
  bool stopped = false;
  int taken = n;
  arena.execute([&] {
    for (int k = 0; k < n && stats_.finite; ++k) {
      // (asked between substeps: a signal ends a long frame within a substep; the state
      // after each substep is the same whether or not anyone asks)
      if (k > 0 && stop && stop()) {
        stopped = true;
        taken = k;
        break;
      }
      if (k % group == 0) begin_cloth_step();
      step_bodies(dt);
      if ((k + 1) % group == 0) {
        ScopedTimer timer(profile_.cloths);
        step_cloths(group * dt);
      }
      // a NaN is caught at once and reported, never stepped on
      if (!check_finite()) stats_.finite = false;
    }
  });
  if (stopped) return taken;
  {
    ScopedTimer timer(profile_.statistics);
    arena.execute([&] { gather_statistics(); });
  }
  return n;
}

void World::step(double dt) {
  begin_cloth_step();
  step_bodies(dt);
  ScopedTimer timer(profile_.cloths);
  step_cloths(dt);
}

void World::step_bodies(double dt) {
  dt_ = dt;
  { ScopedTimer timer(profile_.broad_phase); move_kinematic_bodies(dt); }
  // every dynamic body asleep and no kinematic body moving: no pair, no contact, nothing moves
  bool quiet = true;
  for (int i = 0; i < body_count() && quiet; ++i) {
    quiet = defs_[i].kinematic ? !moving_kinematic(i) : asleep_[i] != 0;
  }
  if (quiet) {
    pairs_.clear();
    contacts_.clear();
    time_ += dt;
    ++stats_.substeps;
    return;
  }
  { ScopedTimer timer(profile_.broad_phase); broad_phase(dt); }
  { ScopedTimer timer(profile_.collisions); resolve_collisions(dt); }
  { ScopedTimer timer(profile_.velocities); update_velocities(dt); }
  { ScopedTimer timer(profile_.contacts); resolve_contacts(dt); }
  { ScopedTimer timer(profile_.shock_propagation); propagate_shocks(); }
  { ScopedTimer timer(profile_.positions); update_positions(dt); }
  { ScopedTimer timer(profile_.sleeping); update_sleeping(dt); }
  time_ += dt;
  ++stats_.substeps;
}

bool World::check_finite() const {
  for (const RigidBodyState& s : states_) {
    if (!(s.x.allFinite() && s.v.allFinite() && s.l.allFinite() && s.q.coeffs().allFinite())) return false;
  }
  for (const Cloth& c : cloths_) {
    if (!(c.positions().allFinite() && c.velocities().allFinite())) return false;
  }
  return true;
}

void World::gather_statistics() {
  double kinetic = 0.0, potential = 0.0;
  for (int i = 0; i < body_count(); ++i) {
    if (defs_[i].kinematic) continue;
    kinetic += kinetic_energy(defs_[i], states_[i]);
    potential -= settings_.gravity.dot(states_[i].x) / defs_[i].inverse_mass;
  }
  double elastic = 0.0, strain = 0.0;
  long long iterations = 0;
  double solver_seconds = 0.0;
  for (const Cloth& c : cloths_) {
    iterations += c.solver_iterations();
    solver_seconds += c.solver_seconds();
    kinetic += c.kinetic_energy();
    potential += c.potential_energy(settings_.gravity);
    elastic += c.elastic_energy();
    strain = std::max(strain, c.max_strain());
  }
  stats_.kinetic_energy = kinetic;
  stats_.potential_energy = potential;
  stats_.elastic_energy = elastic;
  stats_.max_cloth_strain = strain;
  stats_.cloth_solver_iterations = iterations;
  stats_.cloth_solver_seconds = solver_seconds;
  stats_.max_penetration = max_penetration();
  stats_.cloth_penetration = cloth_penetration();
}

double World::max_penetration() const {
  // the pairs the last broad phase kept are the only ones that can touch (the boxes hold
  // the whole step); every sample is tested in both directions at the current poses. Pairs
  // in parallel: the maximum is the same in any order
  return tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, pairs_.size()), 0.0,
      [&](const tbb::blocked_range<std::size_t>& range, double deepest) {
        for (std::size_t k = range.begin(); k < range.end(); ++k) deepest = std::max(deepest, pair_penetration(pairs_[k]));
        return deepest;
      },
      [](double l, double r) { return std::max(l, r); });
}

// Deepest sample of either body of the pair inside the other (or the ground), now (m, >= 0)
double World::pair_penetration(const BodyPair& pair) const {
  // two boxes: the separating axes' depth alone, which no point of either box inside the other
  // can exceed (moving a point at depth d out of a convex body takes a translation >= d)
  OrientedBox box_a, box_b;
  const bool boxes = pair.b != kGround &&
                     body_box(pair.a, mesh_pose(defs_[pair.a], states_[pair.a]), box_a) &&
                     body_box(pair.b, mesh_pose(defs_[pair.b], states_[pair.b]), box_b);
  if (boxes) return box_overlap_depth(box_a, box_b);
  double deepest = 0.0;
  for (const auto& [a, b] : {std::pair{pair.a, pair.b}, std::pair{pair.b, pair.a}}) {
    if (a == kGround || (b != kGround && !defs_[b].shape)) continue;
    const Pose pose_a = mesh_pose(defs_[a], states_[a]);
    const Pose pose_b = b == kGround ? Pose() : mesh_pose(defs_[b], states_[b]);
    const Box3 bounds = b == kGround ? Box3() : defs_[b].shape->bounds();
    const Points& samples = defs_[a].samples;
    for (Eigen::Index s = 0; s < samples.rows(); ++s) {
      const Vec3 x = pose_a.apply(samples.row(s).transpose());
      if (b == kGround) {
        deepest = std::max(deepest, ground_->height - x.y());
        continue;
      }
      const Vec3 p = pose_b.apply_inverse(x);
      if (bounds.contains(p)) deepest = std::max(deepest, -defs_[b].shape->phi(p));
    }
  }
  return deepest;
}

}  // namespace simbake
