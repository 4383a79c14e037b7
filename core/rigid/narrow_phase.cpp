// The narrow phase of the impulse stages: per pair, the points of one body inside (or, for
// speculative contacts, near) the other body or the ground. The samples of body a are tested
// against b's level set at the candidates; the normal is b's level-set gradient turned into
// world space with b's candidate rotation. Two boxes meet by their exact contact instead
// (rigid/box_contact.h).
//
// Swept test. The automatic substeps keep each body's travel per substep to a fraction of
// the thinnest body's thickness, but they are capped (max_substeps) and may be fixed by the
// user; a fast body could then step over a thin wall, or land past its middle, where the
// level set's normal points on through it. So a pair whose relative travel over the step is
// more than 2 travel_fraction of the thinner one's thickness is tested at m evenly spaced
// fractions of the step (poses interpolated between the start and the candidates), and the
// first fraction with a sample inside is the one reported (only fractions where the two
// bounding spheres meet are tested, so the cost does not grow with the speed). No sample
// then moves more than that distance, relative to the other body, between two tests: it
// cannot pass through, nor past the middle of, a body at least 4 travel_fraction x its
// thickness thick.
#include "rigid/narrow_phase.h"

#include "rigid/impulse_stage.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace simbake {

namespace {

constexpr double kCrossingSine = 0.2;   // sin(11.5 deg): box edges closer to parallel are left to the samples

// The narrow phase's view of a step (nothing here changes the model, the data or the scratch)
class NarrowPhase {
 public:
  NarrowPhase(const RigidModel& model, const RigidData& data, const RigidScratch& scratch, const WorldSettings& settings)
      : model_(model), data_(data), scratch_(scratch), settings_(settings) {}

  long long sweep_tests(int a, int b) const;
  void find_penetrations(int a, int b, double margin, long long tests, std::vector<Penetration>& out) const;
  bool box_pair_contact(int a, int b, double s, double margin, std::vector<Penetration>& out) const;
  bool sphere_contact(int a, int b, double margin, std::vector<Penetration>& out) const;
  double contact_margin(int a, int b) const;

 private:
  bool samples_inside(int a, int b, double s, double margin, std::vector<Penetration>& out) const;
  bool box_edge_crossing(int a, int b, double s, double margin, std::vector<Penetration>& out) const;
  Pose pose_at(int i, double s) const { return simbake::pose_at(model_, data_, scratch_, i, s); }
  bool body_box(int i, const Pose& pose, OrientedBox& out) const { return simbake::body_box(model_, i, pose, out); }

  const RigidModel& model_;
  const RigidData& data_;
  const RigidScratch& scratch_;
  const WorldSettings& settings_;
};

// Tests of the pair over this step: 1 for most pairs, m for a fast pair (see above); the
// travel is the relative motion of the centres plus each body's turn times its radius
long long NarrowPhase::sweep_tests(int a, int b) const {
  if (b == kGround) return 1;  // a half-space has no far side
  // the contact stage works at the candidates: the collision stage has turned back whatever
  // approached fast, and a body sliding fast over another keeps its contacts where it ends
  if (scratch_.average_velocities) return 1;
  const Vec3 relative = (scratch_.candidate_x[a] - data_.x[a]) - (scratch_.candidate_x[b] - data_.x[b]);
  const double spacing = 2.0 * settings_.travel_fraction * std::min(model_.defs[a].thickness, model_.defs[b].thickness);
  // the turn's angle 2 atan2(|u|, |w|) of the relative rotation u + w is at most 2 |u| / |w|:
  // a pair that travels less than the spacing even by that bound takes one test, as it would
  // by the exact angle (most pairs; the arc tangent is left to the others)
  auto turn_bound = [&](int i) {
    const Quat d = scratch_.candidate_q[i] * data_.q[i].conjugate();
    const double w = std::abs(d.w());
    return w > 0.5 ? 2.0 * d.vec().norm() / w * model_.defs[i].bounding_radius : std::numeric_limits<double>::infinity();
  };
  if (relative.norm() + turn_bound(a) + turn_bound(b) <= spacing) return 1;
  auto turn = [&](int i) {
    return scratch_.candidate_q[i].angularDistance(data_.q[i]) * model_.defs[i].bounding_radius;
  };
  const double travel = relative.norm() + turn(a) + turn(b);
  const double tests = std::ceil(travel / spacing);
  // (a cap far beyond any speed a scene can mean, so that the count stays an integer)
  return std::isfinite(tests) ? static_cast<long long>(std::clamp(tests, 1.0, 1e15)) : 1;
}


void NarrowPhase::find_penetrations(int a, int b, double margin, long long tests, std::vector<Penetration>& out) const {
  if (b != kGround && !model_.defs[b].shape) return;  // nothing can enter a body without a shape
  // (a fast pair reports the first fraction with a point inside: no margin there, and its
  // samples, not the boxes' exact contact: the impacts of the swept test are the samples')
  if (tests > 1) margin = 0.0;
  long long first = 1, last = tests;
  if (tests > 1) {
    // only while the bounding spheres meet: |d0 + s dd| <= R_a + R_b for the centres' offset
    // d(s), a quadratic in s; so the tests cost the same at any speed
    const Vec3 d0 = data_.x[a] - data_.x[b];
    const Vec3 dd = (scratch_.candidate_x[a] - scratch_.candidate_x[b]) - d0;
    const double reach = model_.defs[a].bounding_radius + model_.defs[b].bounding_radius;
    const double qa = dd.squaredNorm(), qb = d0.dot(dd), qc = d0.squaredNorm() - reach * reach;
    const double discriminant = qb * qb - qa * qc;
    if (discriminant < 0.0 || (qa == 0.0 && qc > 0.0)) return;  // they never meet
    if (qa > 0.0) {  // (else only turning, the centres still: every fraction)
      const double lo = (-qb - std::sqrt(discriminant)) / qa, hi = (-qb + std::sqrt(discriminant)) / qa;
      if (hi < 0.0 || lo > 1.0) return;
      first = std::max(1LL, static_cast<long long>(std::floor(std::max(lo, 0.0) * tests)));
      last = std::min(tests, static_cast<long long>(std::ceil(std::min(hi, 1.0) * tests)));
    }
  }
  for (long long k = first; k <= last; ++k) {
    if (samples_inside(a, b, static_cast<double>(k) / tests, margin, out)) return;
  }
}

// Appends a's samples inside b at fraction s of the step, and with a margin > 0 those outside
// closer than the margin too (but none within kTouching of the surface, see below); true when

// there were any
bool NarrowPhase::samples_inside(int a, int b, double s, double margin, std::vector<Penetration>& out) const {
  const std::size_t before = out.size();
  const Pose pose_a = pose_at(a, s);
  const Points& samples = model_.defs[a].samples;
  // cull in a's mesh frame: only samples within b's bounding sphere (or below the ground
  // plane) can be inside b, and that test costs a fraction of the full one
  Vec3 centre_in_a = Vec3::Zero(), down_in_a = Vec3::Zero();
  double reach = 0.0, ground_offset = 0.0;
  Box3 local_bounds;
  Pose pose_b;
  if (b == kGround) {
    down_in_a = pose_a.rotation.transpose() * Vec3::UnitY();  // world y of a mesh point m: m.down + t.y
    ground_offset = pose_a.translation.y() - model_.ground->height - margin;  // (the margin's plane)
  } else {
    pose_b = pose_at(b, s);
    const Vec3 centre_b = s >= 1.0 ? scratch_.candidate_x[b] : data_.x[b] + s * (scratch_.candidate_x[b] - data_.x[b]);
    centre_in_a = pose_a.apply_inverse(centre_b);
    reach = (model_.defs[b].bounding_radius + margin) * (model_.defs[b].bounding_radius + margin);
    local_bounds = model_.defs[b].shape->bounds();
    local_bounds.min().array() -= margin;
    local_bounds.max().array() += margin;
  }
  // (whole groups and blocks of samples first: most of a body's samples are far from the
  // other; and a block whose sphere lies outside b's box, margin and all, in b's frame: its
  // samples' points would all fail local_bounds.contains)
  const double slackened = b == kGround ? SampleBlock::slackened(ground_offset)
                                        : SampleBlock::slackened(centre_in_a, model_.defs[b].bounding_radius + margin);
  auto near = [&](const SampleBlock& block) {
    if (b == kGround) return block.may_be_below(down_in_a, ground_offset, slackened);
    return block.may_reach(centre_in_a, slackened) && block.may_be_in(local_bounds, pose_b.apply_inverse(pose_a.apply(block.centre)));
  };
  for_sample_blocks(model_.defs[a], near, [&](std::size_t block) {
    const Eigen::Index first = static_cast<Eigen::Index>(block) * SampleBlock::kSize;
    const Eigen::Index end = std::min<Eigen::Index>(first + SampleBlock::kSize, samples.rows());
    for (Eigen::Index k = first; k < end; ++k) {
      const Vec3 m = samples.row(k).transpose();
      double phi;
      Vec3 n;
      if (b == kGround) {
        phi = m.dot(down_in_a) + ground_offset;  // (less the margin)
        if (phi >= 0.0) continue;
        phi += margin;
        n = Vec3::UnitY();
      } else {
        if ((m - centre_in_a).squaredNorm() > reach) continue;
        const Vec3 p = pose_b.apply_inverse(pose_a.apply(m));
        if (!local_bounds.contains(p)) continue;  // outside b's box (and margin) is outside b
        Vec3 n_local;
        phi = model_.defs[b].shape->phi_and_normal(p, n_local);
        // within kTouching of the surface is touching, not penetrating: a sample lying exactly
        // on another body's edge (an exactly aligned stack) would otherwise act, by round-off,
        // with the side face's normal and push the stack sideways
        if (phi >= margin || std::abs(phi) <= kTouching) continue;
        n = pose_b.rotation * n_local;
      }
      out.push_back({a, b, scratch_.candidate_poses[a].apply(m), n, phi, m, s});
    }
  });
  box_edge_crossing(a, b, s, margin, out);
  return out.size() > before;
}

// Two boxes whose edges cross between their samples: crossing edges can sink deep into each
// other (a good part of the samples' spacing) while no sample is inside. When the boxes'
// contact is an edge against an edge (rigid/box_contact.h), the point of a's edge closest to
// b's edge is one more point of a inside b, with the separating axis as its normal and the
// axis's overlap as its depth, carried with both edges (refresh_contact): b's level set there
// would give the normal of a face beside the edge (a side face's, on the rim of a face two
// boxes rest on), and pushed sideways so, an aligned pile of boxes creeps apart. Only for
// edges at least 11.5 degrees apart (kCrossingSine): nearly parallel edges are where boxes
// rest face on face, their axis is ill-conditioned, and the samples hold them (with the
// crossing point there too, an aligned pile ends with its boxes overlapping)
bool NarrowPhase::box_edge_crossing(int a, int b, double s, double margin, std::vector<Penetration>& out) const {
  if (b == kGround || !model_.defs[a].box || !model_.defs[b].box) return false;
  const Pose pose_a = pose_at(a, s), pose_b = pose_at(b, s);
  OrientedBox box_a, box_b;
  BoxContact contact;
  if (!body_box(a, pose_a, box_a) || !body_box(b, pose_b, box_b) ||
      !box_edge_contact(box_a, box_b, margin, contact) || contact.edge_sine < kCrossingSine) {
    return false;
  }
  if (contact.depth <= -margin || std::abs(contact.depth) <= kTouching) return false;
  const Vec3& on_a = contact.points[0].x;
  const Vec3 on_b = on_a + contact.depth * contact.normal;  // the edges' common perpendicular
  const Vec3 m = pose_a.apply_inverse(on_a);
  out.push_back({a, b, scratch_.candidate_poses[a].apply(m), contact.normal, -contact.depth, m, s, true,
                 pose_b.apply_inverse(on_b), pose_b.rotation.transpose() * contact.normal});
  return true;
}

// Two boxes (with box_contacts on): their exact contact (rigid/box_contact.h) instead of the
// samples. An edge crossing another nearly parallel edge between the samples (a box twisted a
// few degrees on the box below) sinks in unseen, and ~100 samples per direction cost more
// than the 15 axes and a clip. The points
// lie on a's surface, each with its depth along the contact normal; like an edge crossing
// (see box_edge_crossing) each is carried by both bodies, a's point in a's frame and the
// matching point of b (depth along the normal) in b's, so that refresh_contact measures the
// separation of the two along the normal carried by b. The pair is found once, for both
// directions. False when the pair is not two boxes or they overlap too deep (see below: the

// samples then, both ways); true when it was found here (its points appended, if any)
bool NarrowPhase::box_pair_contact(int a, int b, double s, double margin, std::vector<Penetration>& out) const {
  if (!settings_.box_contacts || b == kGround || !model_.defs[a].box || !model_.defs[b].box) return false;
  const Pose pose_a = pose_at(a, s), pose_b = pose_at(b, s);
  OrientedBox box_a, box_b;
  body_box(a, pose_a, box_a);
  body_box(b, pose_b, box_b);
  // deeper than a quarter of the thinner box the axis of least overlap may be the far side's
  // (a box driven past a wall's middle in one long step would be pushed on through): the
  // samples then, both ways, with their own guard for deep points (see apply_contact_impulse)
  const double trusted = kTrustedDepth * std::min(model_.defs[a].thickness, model_.defs[b].thickness);
  // with speculative contacts an edge contact brings the faces behind it: a tilted box
  // landing edge first turns about that edge within the step, and its face would close on
  // the other box's with no point of the pair there to stop it. For the same reason a face
  // contact keeps every clipped corner of the incident face within a quarter of the thinner
  // box (the margins' cap), not only those within the margin: the contact stage finds its
  // points once, and a box pressed from above within the stage (a layer landing on it)
  // turns about the corners it rests on and sinks its far side, where the pair would have no
  // point. Such a point is speculative: it only stops the gap closing faster than in a step
  const double point_reach = margin > 0.0 ? trusted : 0.0;
  BoxContact contact, faces;
  if (!box_box_contact(box_a, box_b, margin, contact, margin > 0.0 ? &faces : nullptr, point_reach)) return true;
  if (contact.depth > trusted) return false;
  for (const BoxContact* c : {&contact, &faces}) {
    const Vec3 normal_b = pose_b.rotation.transpose() * c->normal;
    for (int k = 0; k < c->count; ++k) {
      const double depth = c->points[k].depth;
      // (touching is not penetrating, as for the samples; within the reach outside: speculative)
      if (!(depth > kTouching || (margin > 0.0 && depth > -std::max(margin, point_reach)))) continue;
      const Vec3& on_a = c->points[k].x;
      const Vec3 m = pose_a.apply_inverse(on_a);
      out.push_back({a, b, scratch_.candidate_poses[a].apply(m), c->normal, -depth, m, s, true,
                     pose_b.apply_inverse(on_a + depth * c->normal), normal_b});
    }
  }
  return true;
}

// A sphere (body a, its shape an exact sphere about its mesh origin) against the ground or
// body b: one point, the sphere's point nearest b's surface, c - r n, with b's normal n and
// distance at the centre c (at the candidates). Vertices as samples would make a ball a
// polyhedron, which rolls from face to face and loses speed at every face. Exact for the ground, a box or a sphere
// (b's distance is exact out to the centre), and for a convex level set within its band;
// false (the samples then) when the centre is inside b or beyond b's band, or the sphere is
// deeper than is trusted. True when found here (its point appended, if near enough).
bool NarrowPhase::sphere_contact(int a, int b, double margin, std::vector<Penetration>& out) const {
  const RigidBodyDef& def = model_.defs[a];
  if (def.sphere == nullptr) return false;
  const double r = def.sphere->radius();
  const Pose& pose_a = scratch_.candidate_poses[a];
  const Vec3& centre = pose_a.translation;
  double at_centre;
  Vec3 n;
  if (b == kGround) {
    at_centre = centre.y() - model_.ground->height;
    n = Vec3::UnitY();
  } else {
    const SignedDistance& shape = *model_.defs[b].shape;
    const Pose pose_b = pose_at(b, 1.0);
    Vec3 n_local;
    at_centre = shape.phi_and_normal(pose_b.apply_inverse(centre), n_local);
    if (at_centre <= 0.0 || at_centre >= shape.exterior_reach()) return false;
    n = pose_b.rotation * n_local;
  }
  const double phi = at_centre - r;
  const double thinner = b == kGround ? def.thickness : std::min(def.thickness, model_.defs[b].thickness);
  if (-phi > kTrustedDepth * thinner) return false;
  // (touching is not penetrating, as for the samples; within the margin outside: speculative)
  if (phi >= margin || std::abs(phi) <= kTouching) return true;
  const Vec3 x = centre - r * n;
  out.push_back({a, b, x, n, phi, pose_a.apply_inverse(x), 1.0});
  return true;
}

// Body i's K at world point x, lever arm from its candidate centre of mass; zero for the

// as impulses land: a box resting on a falling box, both at the same velocity, touches
// nothing at the candidates until the lower one is stopped, and then sinks g dt^2 into it
// within the step unseen (the next step's collision stage catches it, one level of a stack
// per step). So the stage also takes the points closer than a margin to the other body, with
// the gap they have at the start of the step, gap = phi - dt v.n (phi at the candidate, v the
// average velocity): such a point may close its gap within the step, v.n >= -gap / dt, and no
// more (the constraint of speculative contacts in game engines, Catto 2013). The margin is
// what the bodies' speeds and gravity may move them over the step relative to each other
// (at most the broad phase's margins, which hold the pair's boxes): half a step at each body's
// speed plus gravity over two steps, at least the penetration slop; never more than a quarter
// of the thinner body (where level-set normals are trusted) nor outside what a grid's
// exterior band holds
double NarrowPhase::contact_margin(int a, int b) const {
  // (not with cloths: a cloth between two bodies, or a body and the ground, is no part of
  // their contact, and closing the gap it fills pushes the bodies' edges through it)
  if (!scratch_.speculative) return 0.0;
  const double g = settings_.gravity.norm();
  double margin = settings_.penetration_slop + 2.0 * g * scratch_.dt * scratch_.dt;
  double cap = std::numeric_limits<double>::infinity();
  for (int i : {a, b}) {
    if (i == kGround) continue;
    margin += 0.5 * scratch_.dt * scratch_.candidate_v[i].norm();  // (the velocity over the step, gravity in)
    cap = std::min(cap, kTrustedDepth * model_.defs[i].thickness);
  }
  for (int i : {a, b}) {
    if (i != kGround && model_.defs[i].shape) cap = std::min(cap, 0.5 * model_.defs[i].shape->exterior_reach());
  }
  return std::min(margin, cap);
}

}  // namespace

// Every pair's penetrating samples, both directions (pair order, then sample order); two boxes
// by their exact contact, once for the pair. Pairs are independent and read-only here, so they
// run in parallel; each writes only its own list, so the result is the same for any number of
// threads. With reuse (the contact stage), a pair whose bodies took no collision impulse keeps
// the list the collision stage found: its candidates are the same, bit for bit (x + dt (v + dt
// g) either way, the same rotation), and so are its margin (see contact_margin) and its one
// test; the narrow phase then runs once per step for most of a resting pile
void find_pair_penetrations(const RigidModel& model, const RigidData& data, RigidScratch& scratch,
                            const WorldSettings& settings, bool speculative, bool reuse) {
  const NarrowPhase narrow(model, data, scratch, settings);
  std::vector<std::vector<Penetration>>& out = scratch.pair_points;
  const std::vector<BodyPair>& pairs = scratch.pairs;
  out.resize(pairs.size());
  scratch.single_test.resize(pairs.size());
  tbb::parallel_for(std::size_t(0), pairs.size(), [&](std::size_t k) {
    const int a = pairs[k].a, b = pairs[k].b;
    if (reuse && scratch.single_test[k] && !scratch.collided[a] && (b == kGround || !scratch.collided[b])) return;
    out[k].clear();
    const double margin = speculative ? narrow.contact_margin(a, b) : 0.0;
    const long long tests = narrow.sweep_tests(a, b);  // (the same both ways)
    scratch.single_test[k] = tests == 1;
    if (tests == 1 && narrow.box_pair_contact(a, b, 1.0, margin, out[k])) return;
    // a sphere by its nearest point (two spheres: once, for the pair)
    const bool a_sphere = tests == 1 && narrow.sphere_contact(a, b, margin, out[k]);
    if (!a_sphere) narrow.find_penetrations(a, b, margin, tests, out[k]);
    if (b == kGround || (a_sphere && model.defs[b].sphere != nullptr)) return;
    if (!(tests == 1 && narrow.sphere_contact(b, a, margin, out[k]))) narrow.find_penetrations(b, a, margin, tests, out[k]);
  });
}

namespace {

// p's normal and distance from body b at b's pose, for the point x of a
void refresh_against(const RigidModel& model, const Pose& pose_b, const Vec3& x, Penetration& p) {
  if (p.crossing) {  // the two edges' points, carried by their bodies, along the normal
    p.n = pose_b.rotation * p.normal_b;
    p.phi = p.n.dot(x - pose_b.apply(p.local_b));
    return;
  }
  Vec3 n_local;
  p.phi = model.defs[p.b].shape->phi_and_normal(pose_b.apply_inverse(x), n_local);
  p.n = pose_b.rotation * n_local;
}

}  // namespace

// Moves a contact's sample with its body's candidate and takes b's normal there
// (at the fraction of the step where it was found: see the swept test)
void refresh_contact(const RigidModel& model, const RigidData& data, const RigidScratch& scratch, Penetration& p) {
  const Vec3& m = p.local;
  p.x = scratch.candidate_poses[p.a].apply(m);
  if (p.b == kGround) {
    p.phi = p.x.y() - model.ground->height;
    p.n = Vec3::UnitY();
  } else if (p.s >= 1.0) {
    refresh_against(model, scratch.candidate_poses[p.b], p.x, p);
  } else {
    refresh_against(model, pose_at(model, data, scratch, p.b, p.s), pose_at(model, data, scratch, p.a, p.s).apply(m), p);
  }
}

// Body i as an oriented box at the pose, when its shape is a box
bool body_box(const RigidModel& model, int i, const Pose& pose, OrientedBox& out) {
  if (model.defs[i].box == nullptr) return false;
  out = {pose.translation, pose.rotation, model.defs[i].box->half()};
  return true;
}

}  // namespace simbake
