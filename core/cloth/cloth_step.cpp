// One cloth's step, after the rigid bodies have moved (DESIGN.md, "The world step", stage 6).
//
// The cloth computes its internal forces and new velocities itself (integrators.h), with the
// contacts resting on still surfaces held inside its implicit solve; its contacts with the
// bodies and the ground (contact/cloth_body_contact.h: the candidates x + dt v pushed out to
// the cloth's thickness, Coulomb friction, the opposite momentum to dynamic bodies) then
// alternate with strain limiting (strain_limiting.h) and self-collision (self_collision.h),
// then self-collision and strain limiting go in rounds (self-collision with the kinematic
// boxes and meshes as obstacles of infinite mass: contact/cloth_obstacles.h), then a cloth
// pinched between two surfaces holds them apart, then positions. Each of these moves only the
// velocities v, so that the candidates x + dt v respect them all; the last word is
// self-collision's, so that no layer passes through another. A cloth attached to a body
// (contact/cloth_attachment.h) has its attached vertices' velocities set first, which every
// stage keeps, and they are put on the body's surface after the positions; a dynamic body
// takes back what the attachment gave the cloth over the stages it acts in (measured as
// momentum here, around them).
#include "cloth/cloth_step.h"

#include <algorithm>

namespace simbake {

namespace {

constexpr int kStrainCollisionPasses = 12; // limiter-then-collisions passes per step (at most)
constexpr double kStrainSlack = 0.02;      // a pass is enough once no edge is past the limit by 2% of it
constexpr double kFinalSlack = 0.002;      // the end-of-step rounds: done once no edge is past the limit by 0.2% of it
                                           // (within the QA's and the render-ready test's 1%)
constexpr int kFinalRounds = 4;            // strain limiting and self-collision in turn at the end (at most)
constexpr int kSelfCollisionPasses = 3;    // of those passes, the first ones that also collide the cloth with itself
constexpr int kZoneRounds = 3;             // impact zones, then strain limiting around them, in turn (at most)
// A cloth stretched past this many times its strain limit gives way to the kinematic
// obstacles: the vertices within an edge (at least twice its thickness) of one are no longer
// kept out of it (contact/cloth_obstacles.h, yielding). A keyed box pushing a cloth held by
// its pins (or a heavier part of itself) would otherwise carry it along without end: the
// strain limiter cannot shorten the edges from the pins to the box, and each of its global
// passes runs to its iteration cap. Shipped scenes stay within 1% of their limit. Past it,
// the global passes cannot bring the cloth back within a step either (what holds it there
// holds it): the rest of the step limits strain by the Gauss-Seidel sweeps alone
constexpr double kGiveStrain = 3.0;

// The sub-stages of one cloth's step, each timed into its own profile entry
class ClothStep {
 public:
  ClothStep(SteppedCloth& stepped, ContactBodies& bodies, double dt, const ClothStepSettings& settings,
            StageProfile& profile, SelfCollisionStatistics& stats)
      : cloth_(stepped.cloth), contact_(stepped.contact), self_(stepped.self), obstacles_(stepped.obstacles),
        attachment_(stepped.attachment), bodies_(bodies), dt_(dt), settings_(settings), profile_(profile),
        stats_(stats), limit_(stepped.cloth.material().strain_limit) {
    if (attachment_) attach();
    self_settings_.thickness = contact_.thickness();
    self_settings_.friction = contact_.friction();
    self_settings_.support = &contact_.support();
    // a cloth past kGiveStrain x its limit at the step's start gives (the obstacles let it in,
    // below) and is limited by sweeps alone for the step
    sweeps_only_ = past_give(cloth_.max_strain());
    const bool give = sweeps_only_;
    // the kinematic boxes and meshes join self-collision as obstacles (contact/cloth_obstacles.h):
    // its calls then see the cloth's vertices and the obstacles' in one set of arrays
    if (self_ && obstacles_.select(bodies_)) self_.emplace(cloth_.triangles(), cloth_.vertex_count(), obstacles_.meshes());
    if (self_) self_->begin_step();  // the step's self-collision budgets start again
    joined_ = self_ && !obstacles_.empty();
    if (joined_) {
      // (giving, the vertices within an edge of an obstacle: a coarse cloth meets a box's
      // face and edges inside its triangles, its vertices an edge away)
      const double reach = std::max(2.0 * contact_.thickness(), contact_.mean_edge());
      obstacles_.begin_step(cloth_, bodies_, contact_.inverse_mass(), dt_, give ? reach : 0.0);
      self_settings_.obstacle_motion = &obstacles_.motions();
      // attached to an obstacle: its vertices and the obstacle's move as one (the same field),
      // so an impact zone holding both moves with it rather than holding still
      const std::vector<int>& chosen = obstacles_.bodies();
      const auto found = attachment_ ? std::find(chosen.begin(), chosen.end(), attachment_->body()) : chosen.end();
      if (found != chosen.end()) self_settings_.attachment_motion = &obstacles_.motions()[found - chosen.begin()];
      if (obstacles_.any_yielding()) {
        // the vertices let in: self-collision no longer keeps them out of the obstacles, and a
        // moving obstacle's contacts no longer push them (it passes through them)
        self_settings_.yielding = &obstacles_.yielding();
        ++stats_.let_in;
        for (int b : obstacles_.bodies()) {
          if (!bodies_.body(b).still) bodies_.set_let_in(b, &obstacles_.yielding());
        }
      }
    }
  }

  bool self_collision() const { return self_.has_value(); }
  // whether the cloth gave this step (stretched past kGiveStrain x its limit)
  bool gave() const { return sweeps_only_; }

  // internal forces and the velocity update, holding the contacts resting on still surfaces;
  // the contacts the solve holds, and their friction after it, are contacts' time
  void update_velocities() {
    std::vector<ClothContactConstraint> constraints;
    {
      StageTimer timer(profile_, Stage::kClothContacts);
      if (settings_.contacts_in_solve) {
        contact_.contact_constraints(cloth_, bodies_, constraints);
      } else {
        contact_.forget_touches();
      }
    }
    {
      StageTimer timer(profile_, Stage::kClothForces);
      reaction_.measured(cloth_, [&] { cloth_.update_velocities(dt_, settings_.gravity, &constraints); });
      // (the surfaces' impulses on the contacts held in the solve are theirs, not the attachment's)
      for (const ClothContactConstraint& c : constraints) {
        if (reaction_.on()) reaction_.not_given(cloth_, c.vertex, c.impulse * c.normal + c.friction);
      }
    }
    {
      StageTimer timer(profile_, Stage::kClothContacts);
      contact_.apply_constraint_impulses(cloth_, bodies_, constraints);
    }
  }

  void collide_with_bodies() {
    StageTimer timer(profile_, Stage::kClothContacts);
    contact_.collide(cloth_, bodies_, dt_);
  }

  // (a global pass that leaves the cloth past kGiveStrain x its limit: sweeps alone from then on)
  void limit_strain(bool global) {
    StageTimer timer(profile_, Stage::kClothStrain);
    reaction_.measured(cloth_, [&] { cloth_.limit_strain(dt_, global && !sweeps_only_); });
    if (global && !sweeps_only_ && past_give(cloth_.candidate_strain(dt_))) sweeps_only_ = true;
  }

  // self-collision's repulsions between layers closer than the thickness
  void repel() {
    on_self([&](const Points& x, Points& v, const Eigen::VectorXd& w, const SelfCollisionSettings& settings) {
      self_->repel(x, v, w, dt_, settings, stats_);
      return true;
    });
  }

  // `passes` passes of self-collision's continuous collisions; true when none is left
  bool collide_self(int passes) {
    return on_self([&](const Points& x, Points& v, const Eigen::VectorXd& w, const SelfCollisionSettings& settings) {
      return self_->collide(x, v, w, dt_, settings, stats_, passes);
    });
  }

  // Strain limiting, collisions with bodies and with itself in turn, until they agree: each
  // can undo a little of what the others did (a collision stretches an edge the limiter
  // fixed; an impulse against a layer pushes a vertex towards a body). Self-collision takes
  // part in the first few passes only (it costs most); what it leaves is small
  void strain_and_collision_passes() {
    for (int pass = 0; pass < kStrainCollisionPasses; ++pass) {
      limit_strain(pass == 0);
      collide_with_bodies();
      bool clear = true;
      if (self_ && pass < kSelfCollisionPasses) {
        // layers the body contacts pressed into one plane (each at the thickness from the
        // surface) are pushed apart again, the outer one outwards
        repel();
        clear = collide_self(1);
      }
      if (clear && (limit_ <= 0.0 || cloth_.candidate_strain(dt_) <= limit_ * (1.0 + kStrainSlack))) break;
    }
  }

  // The cloth against itself has the last word: repulsions (the last body contacts may have
  // pressed layers into one plane) and collision impulses; then strain limiting (all edges
  // at once, converged) and collisions in turn, until the collisions find nothing ahead and
  // leave no edge past the limit (their impulses alone can stretch edges well past it after
  // a converged limiter). Body contacts take no part in these rounds: they would pull the
  // layers against a body apart again, and the strain with them. True when the cloth is clear
  bool self_collision_rounds() {
    repel();
    collide_self(1);
    bool clear = false;
    for (int round = 0; round < kFinalRounds; ++round) {
      limit_strain(true);
      clear = collide_self(2);
      if (clear && !over_limit()) break;
    }
    return clear;
  }

  // Rigid impact zones for what is left, so that nothing passes a layer through another.
  // Impact zones move their vertices rigidly, which stretches the edges from a zone to the
  // cloth around it: those edges are limited again with the zones held still (only the
  // vertices around them move), and what that brings into collision joins a zone in turn; the
  // zones have the last word. A round that finds the cloth clear but an edge past the limit
  // limits it again, then collides: a zone's rigid velocity stretches its own edges too
  // (x + dt (v + w x r) is no rotation), and so may the rounds before (when they ran out)
  void impact_zone_rounds(bool clear) {
    for (int round = 0; round < kZoneRounds; ++round) {
      if (clear) {
        if (!over_limit() || round + 1 == kZoneRounds) break;
        limit_strain(true);
        clear = collide_self(2);
        if (clear) continue;
      }
      on_self([&](const Points& x, Points& v, const Eigen::VectorXd& w, const SelfCollisionSettings& settings) {
        self_->impact_zones(x, v, w, dt_, settings, stats_);
        return true;
      });
      if (!over_limit()) break;
      if (round + 1 == kZoneRounds) break;
      if (!sweeps_only_) push_zones();
      clear = collide_self(1);
    }
  }

  // a step whose self-collision ran out of a budget (SelfCollisionSettings: candidate pairs,
  // pairs visited) is not known to be free of crossings: the cloth holds still for it, as
  // when the impact zones do not settle, and stays free of them (counted in the statistics,
  // and the QA warns)
  void hold_still_if_over_budget() {
    if (!self_ || !self_->over_budget()) return;
    const std::vector<char>& attached = cloth_.model().attached;  // (they move as their body does)
    for (int k = 0; k < cloth_.vertex_count(); ++k) {
      if (!attached[k]) cloth_.velocities().row(k).setZero();
    }
  }

  void hold_pinched_bodies() {
    StageTimer timer(profile_, Stage::kClothContacts);
    contact_.hold_pinched_bodies(cloth_, bodies_, dt_);
  }

  // positions; the attached vertices put on their body's surface, and a dynamic body given
  // what the attachment gave the cloth, opposite
  void update_positions() {
    cloth_.update_positions(dt_);
    if (!attachment_) return;
    attachment_->place(cloth_);
    if (!reaction_.on()) return;
    const int b = attachment_->body();
    StageTimer timer(profile_, Stage::kClothContacts);
    bodies_.apply_wrench(b, -reaction_.given().linear, -reaction_.given().angular);
    if (bodies_.asleep(b)) bodies_.wake(b);
  }

 private:
  // The attached vertices' velocities over the step, and their motion for the impact zones;
  // with a dynamic body, the reaction's bookkeeping (contact/cloth_attachment.h) starts, and
  // counts the velocities given
  void attach() {
    if (attachment_->reacting(bodies_)) {
      reaction_.begin(cloth_, bodies_.body(attachment_->body()).center, settings_.gravity, dt_);
    }
    reaction_.measured(cloth_, [&] { attachment_->prescribe(cloth_, bodies_, dt_); });
    self_settings_.attached = &cloth_.model().attached;
    self_settings_.attachment_motion = &attachment_->motion();
  }

  // whether self-collision's change of the cloth's momentum is counted as the attachment's
  // (on_self): with a dynamic body, and no obstacle, pin or still surface (the ground, a
  // static body holding a vertex this step) that could have absorbed some of it too
  bool self_counted() const {
    if (!reaction_.on() || joined_) return false;
    const ClothModel& m = cloth_.model();
    for (int k = 0; k < cloth_.vertex_count(); ++k) {
      if ((m.pinned[k] && !m.attached[k]) || contact_.support()[k].squaredNorm() > 0.0) return false;
    }
    return true;
  }

  bool over_limit() const { return limit_ > 0.0 && cloth_.candidate_strain(dt_) > limit_ * (1.0 + kFinalSlack); }
  bool past_give(double strain) const { return limit_ > 0.0 && strain > kGiveStrain * limit_; }

  // the edges around the zones limited with the zones held still, and the zones taking the
  // pushes of those edges as rigid bodies, so that momentum is kept (held still, they would
  // absorb them)
  void push_zones() {
    Points pushed;
    {
      StageTimer timer(profile_, Stage::kClothStrain);
      const std::vector<char>& zones = self_->zone_vertices();
      reaction_.measured(cloth_, [&] {
        pushed = cloth_.limit_strain_holding(dt_, joined_ ? obstacles_.cloth_part(zones) : zones);
      });
      // (what the held zones absorbed, self-collision gives back to them below: not the
      // attachment's, so taken out here unless that is counted too)
      if (reaction_.on() && !self_counted()) {
        for (int k = 0; k < cloth_.vertex_count(); ++k) reaction_.not_given(cloth_, k, -Vec3(pushed.row(k).transpose()));
      }
    }
    on_self([&](const Points& x, Points& v, const Eigen::VectorXd& w, const SelfCollisionSettings& settings) {
      self_->push_zones(x, v, w, settings, joined_ ? obstacles_.padded(pushed) : pushed);
      return true;
    });
  }

  // f(x, v, inverse mass, settings) on the cloth's arrays, or on those joined with the obstacles'
  // (with a dynamic body its impulses on the attached vertices, which absorb them, are the
  // attachment's: counted when nothing else of infinite mass takes part, no obstacle, pin or
  // still surface under the cloth, and the cloth was not held still)
  template <class F>
  bool on_self(F&& f) {
    StageTimer timer(profile_, Stage::kClothSelfCollision);
    if (!joined_) {
      const bool counted = self_counted();
      const long long stills = stats_.stills;
      const ClothMomentum before = counted ? cloth_momentum(cloth_, reaction_.center()) : ClothMomentum();
      const bool result = f(cloth_.positions(), cloth_.velocities(), contact_.inverse_mass(), self_settings_);
      if (counted && stats_.stills == stills) reaction_.add_since(cloth_, before);
      return result;
    }
    obstacles_.load(cloth_.velocities(), contact_.support());
    SelfCollisionSettings settings = self_settings_;
    settings.support = &obstacles_.support();
    const bool result = f(obstacles_.positions(), obstacles_.velocities(), obstacles_.inverse_mass(), settings);
    obstacles_.store(cloth_.velocities());
    return result;
  }

  Cloth& cloth_;
  ClothBodyContact& contact_;
  std::optional<SelfCollision>& self_;
  ClothObstacles& obstacles_;
  std::optional<ClothAttachment>& attachment_;
  ContactBodies& bodies_;
  const double dt_;
  const ClothStepSettings& settings_;
  StageProfile& profile_;
  SelfCollisionStatistics& stats_;
  const double limit_;                   // the cloth's strain limit (0: none)
  SelfCollisionSettings self_settings_;
  bool joined_ = false;                  // the obstacles joined self-collision this step
  bool sweeps_only_ = false;             // the cloth gave: strain limited by sweeps alone
  AttachmentReaction reaction_;          // attached to a dynamic body: what the attachment gives
};

}  // namespace

bool step_cloth(SteppedCloth& cloth, ContactBodies& bodies, double dt, const ClothStepSettings& settings,
                StageProfile& profile, SelfCollisionStatistics& stats) {
  ClothStep step(cloth, bodies, dt, settings, profile, stats);
  step.update_velocities();
  step.collide_with_bodies();
  if (step.self_collision()) step.repel();
  step.strain_and_collision_passes();
  if (step.self_collision()) {
    step.impact_zone_rounds(step.self_collision_rounds());
    step.hold_still_if_over_budget();
  }
  step.hold_pinched_bodies();
  step.update_positions();
  return step.gave();
}

}  // namespace simbake
