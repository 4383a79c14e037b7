// The rigid-body stages of World::step, after Guendelman, Bridson and Fedkiw, "Nonconvex rigid
// bodies with stacking" (SIGGRAPH 2003) and the seed notes.
//
// Candidates. Both impulse stages work on candidate end-of-step states: the collision stage
// advances x by dt (v + dt g) (forces included) and q by the torque-free rotation; the
// contact stage, after gravity has been added to v, advances x by dt v. Every impulse
// changes the start-of-step v and L of the bodies it touches, and so their candidates, which
// are recomputed at once.
//
// Velocities at a point, v = V + omega x (x - X) with X the candidate centre of mass.
// Collisions use start-of-step velocities, omega = I^-1 L (updated exactly by each impulse,
// omega += I^-1 (r x J)). Contacts use the average velocities that update_positions will
// realize, as the notes' "Average velocities" slide requires: V_avg = (X(t+dt) - X(t)) / dt
// = V, and omega_avg = unrotate(q_new q^-1) / dt with q_new the candidate orientation. Within
// a contact sweep omega_avg follows each impulse to first order (the same I^-1 (r x J)); the
// candidates and omega_avg are recomputed exactly at the start of every sweep, so once the
// sweeps converge the velocities are exactly the average ones.
//
// Materials. A pair's friction is the geometric mean sqrt(mu_a mu_b) and its restitution the
// larger of the two (both symmetric and both give back the common value when equal; max
// lets a bouncy ball bounce on a default, non-bouncy ground).
#include "levelset/signed_distance.h"
#include "rigid/box_contact.h"
#include "rigid/impulse.h"
#include "world/world.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

namespace simbake {

namespace {
constexpr double kTrustedDepth = 0.25;  // of the thinner body's thickness: deeper, the level
                                        // set's normal no longer points the way out
constexpr double kImpactSpeed = 1.0;    // (m/s) slower approaches are settling, not impacts
constexpr double kCrossingSine = 0.2;   // sin(11.5 deg): box edges closer to parallel are left to the samples
}  // namespace

// ---------------------------------------------------------------------------------------
// Candidates and point velocities

void World::begin_impulse_stage(double dt, bool with_forces, bool average_velocities) {
  dt_ = dt;
  candidates_with_forces_ = with_forces;
  average_velocities_ = average_velocities;
  // (each body on its own: in parallel)
  tbb::parallel_for(0, body_count(), [&](int i) {
    if (asleep_[i]) return;
    const RigidBodyDef& def = defs_[i];
    inverse_inertia_[i] = def.kinematic ? Mat3::Zero() : world_inverse_inertia(def, states_[i].q);
    if (def.kinematic) omega_[i] = spin_[i];
    else if (!average_velocities) omega_[i] = inverse_inertia_[i] * states_[i].l;
    update_candidate(i);
  });
  log_.stale.clear();
}

void World::update_candidate(int i) {
  const RigidBodyDef& def = defs_[i];
  const RigidBodyState& s = states_[i];
  RigidBodyState& c = candidates_[i];
  c = s;
  if (def.kinematic) {
    c.x = s.x + dt_ * s.v;
    c.q = prescribed_rotation(s.q, spin_[i], dt_);
  } else {
    const Vec3 v = candidates_with_forces_ ? Vec3(s.v + dt_ * settings_.gravity) : s.v;
    c.x = s.x + dt_ * v;
    c.v = v;
    c.q = free_rotation(def, s.q, s.l, dt_);
    if (average_velocities_) {
      // (an isotropic body turns at L / I exactly, the rotation vector's shorter way round
      // while it turns less than half a turn in the step)
      const Vec3 spin = def.inverse_inertia[0] * s.l;
      omega_[i] = def.isotropic && dt_ * spin.norm() < 3.0 ? spin
                                                           : Vec3(rotation_vector_from_quat(c.q * s.q.conjugate()) / dt_);
    }
  }
  candidate_poses_[i] = mesh_pose(def, c);
  stale_[i] = 0;
  ++version_[i];
}

// Marks body i's candidate as behind its velocities; the log's list keeps the refresh in
// proportion to the bodies that took impulses, not to the world
void World::mark_stale(int i, ImpulseLog& log) {
  if (!stale_[i]) log.stale.push_back(i);
  stale_[i] = 1;
}

void World::refresh_stale_candidates(ImpulseLog& log) {
  // (a body refreshed by a whole-world pass since it was listed is no longer stale)
  for (int i : log.stale) {
    if (stale_[i]) update_candidate(i);
  }
  log.stale.clear();
}

Vec3 World::point_velocity(int i, const Vec3& x) const {
  if (i == kGround) return Vec3::Zero();
  return states_[i].v + omega_[i].cross(x - candidates_[i].x);
}

// ---------------------------------------------------------------------------------------
// Narrow phase: the samples of body a tested against b's level set at the candidates.
// The normal is b's level-set gradient turned into world space with b's candidate rotation.
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

// Tests of the pair over this step: 1 for most pairs, m for a fast pair (see above); the
// travel is the relative motion of the centres plus each body's turn times its radius
long long World::sweep_tests(int a, int b) const {
  if (b == kGround) return 1;  // a half-space has no far side
  // the contact stage works at the candidates: the collision stage has turned back whatever
  // approached fast, and a body sliding fast over another keeps its contacts where it ends
  if (average_velocities_) return 1;
  const Vec3 relative = (candidates_[a].x - states_[a].x) - (candidates_[b].x - states_[b].x);
  const double spacing = 2.0 * settings_.travel_fraction * std::min(defs_[a].thickness, defs_[b].thickness);
  // the turn's angle 2 atan2(|u|, |w|) of the relative rotation u + w is at most 2 |u| / |w|:
  // a pair that travels less than the spacing even by that bound takes one test, as it would
  // by the exact angle (most pairs; the arc tangent is left to the others)
  auto turn_bound = [&](int i) {
    const Quat d = candidates_[i].q * states_[i].q.conjugate();
    const double w = std::abs(d.w());
    return w > 0.5 ? 2.0 * d.vec().norm() / w * defs_[i].bounding_radius : std::numeric_limits<double>::infinity();
  };
  if (relative.norm() + turn_bound(a) + turn_bound(b) <= spacing) return 1;
  auto turn = [&](int i) {
    return candidates_[i].q.angularDistance(states_[i].q) * defs_[i].bounding_radius;
  };
  const double travel = relative.norm() + turn(a) + turn(b);
  const double tests = std::ceil(travel / spacing);
  // (a cap far beyond any speed a scene can mean, so that the count stays an integer)
  return std::isfinite(tests) ? static_cast<long long>(std::clamp(tests, 1.0, 1e15)) : 1;
}

// Mesh pose of body i at fraction s of the step, between its start and its candidate
Pose World::pose_at(int i, double s) const {
  if (s >= 1.0) return candidate_poses_[i];
  RigidBodyState between = candidates_[i];
  between.x = states_[i].x + s * (candidates_[i].x - states_[i].x);
  between.q = states_[i].q.slerp(s, candidates_[i].q);
  return mesh_pose(defs_[i], between);
}

void World::find_penetrations(int a, int b, double margin, long long tests, std::vector<Penetration>& out) const {
  if (b != kGround && !defs_[b].shape) return;  // nothing can enter a body without a shape
  // (a fast pair reports the first fraction with a point inside: no margin there, and its
  // samples, not the boxes' exact contact: the impacts of the swept test are the samples')
  if (tests > 1) margin = 0.0;
  long long first = 1, last = tests;
  if (tests > 1) {
    // only while the bounding spheres meet: |d0 + s dd| <= R_a + R_b for the centres' offset
    // d(s), a quadratic in s; so the tests cost the same at any speed
    const Vec3 d0 = states_[a].x - states_[b].x;
    const Vec3 dd = (candidates_[a].x - candidates_[b].x) - d0;
    const double reach = defs_[a].bounding_radius + defs_[b].bounding_radius;
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
bool World::samples_inside(int a, int b, double s, double margin, std::vector<Penetration>& out) const {
  const std::size_t before = out.size();
  const Pose pose_a = pose_at(a, s);
  const Points& samples = defs_[a].samples;
  // cull in a's mesh frame: only samples within b's bounding sphere (or below the ground
  // plane) can be inside b, and that test costs a fraction of the full one
  Vec3 centre_in_a = Vec3::Zero(), down_in_a = Vec3::Zero();
  double reach = 0.0, ground_offset = 0.0;
  Box3 local_bounds;
  Pose pose_b;
  if (b == kGround) {
    down_in_a = pose_a.rotation.transpose() * Vec3::UnitY();  // world y of a mesh point m: m.down + t.y
    ground_offset = pose_a.translation.y() - ground_->height - margin;  // (the margin's plane)
  } else {
    pose_b = pose_at(b, s);
    const Vec3 centre_b = s >= 1.0 ? candidates_[b].x : states_[b].x + s * (candidates_[b].x - states_[b].x);
    centre_in_a = pose_a.apply_inverse(centre_b);
    reach = (defs_[b].bounding_radius + margin) * (defs_[b].bounding_radius + margin);
    local_bounds = defs_[b].shape->bounds();
    local_bounds.min().array() -= margin;
    local_bounds.max().array() += margin;
  }
  // (whole blocks of samples first: most of a body's samples are far from the other)
  const std::vector<SampleBlock>& blocks = defs_[a].sample_blocks;
  const double slackened = b == kGround ? SampleBlock::slackened(ground_offset)
                                        : SampleBlock::slackened(centre_in_a, defs_[b].bounding_radius + margin);
  for (std::size_t block = 0; block < blocks.size(); ++block) {
    if (b == kGround ? !blocks[block].may_be_below(down_in_a, ground_offset, slackened)
                     : !blocks[block].may_reach(centre_in_a, slackened)) {
      continue;
    }
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
        phi = defs_[b].shape->phi_and_normal(p, n_local);
        // within kTouching of the surface is touching, not penetrating: a sample lying exactly
        // on another body's edge (an exactly aligned stack) would otherwise act, by round-off,
        // with the side face's normal and push the stack sideways
        if (phi >= margin || std::abs(phi) <= kTouching) continue;
        n = pose_b.rotation * n_local;
      }
      out.push_back({a, b, candidate_poses_[a].apply(m), n, phi, m, s});
    }
  }
  box_edge_crossing(a, b, s, margin, out);
  return out.size() > before;
}

// Two boxes whose edges cross between their samples: samples 0.125 m apart on 0.5 m boxes let
// crossing edges sink 50 mm into each other in the 1000-box pile (measured from the poses by
// the separating axes, benchmarks/peers/scenes.py) while no sample was inside. When the
// boxes' contact is an edge against an edge (rigid/box_contact.h), the point of a's edge
// closest to b's edge is one more point of a inside b, with the separating axis as its normal
// and the axis's overlap as its depth, carried with both edges (refresh_contact): b's level
// set there would give the normal of a face beside the edge (a side face's, on the rim of a
// face two boxes rest on), and pushed sideways so, the 1000 aligned boxes crept off the pile
// at 1-9 m/s. Only for edges at least 11.5 degrees apart (kCrossingSine): nearly parallel
// edges are where boxes rest face on face, their axis is ill-conditioned, and the samples
// hold them (measured: the aligned pile ended with 20 mm of overlap without this bound)
bool World::box_edge_crossing(int a, int b, double s, double margin, std::vector<Penetration>& out) const {
  if (b == kGround || !defs_[a].box || !defs_[b].box) return false;
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
  out.push_back({a, b, candidate_poses_[a].apply(m), contact.normal, -contact.depth, m, s, true,
                 pose_b.apply_inverse(on_b), pose_b.rotation.transpose() * contact.normal});
  return true;
}

// Two boxes (with box_contacts on): their exact contact (rigid/box_contact.h) instead of the
// samples. The samples of a 0.5 m box are 0.125 m apart: an edge crossing another nearly
// parallel edge between them (a box twisted a few degrees on the box below) sinks 12 mm in
// unseen, and ~100 samples per direction cost more than the 15 axes and a clip. The points
// lie on a's surface, each with its depth along the contact normal; like an edge crossing
// (see box_edge_crossing) each is carried by both bodies, a's point in a's frame and the
// matching point of b (depth along the normal) in b's, so that refresh_contact measures the
// separation of the two along the normal carried by b. The pair is found once, for both
// directions. False when the pair is not two boxes or they overlap too deep (see below: the
// samples then, both ways); true when it was found here (its points appended, if any)
bool World::box_pair_contact(int a, int b, double s, double margin, std::vector<Penetration>& out) const {
  if (!settings_.box_contacts || b == kGround || !defs_[a].box || !defs_[b].box) return false;
  const Pose pose_a = pose_at(a, s), pose_b = pose_at(b, s);
  OrientedBox box_a, box_b;
  body_box(a, pose_a, box_a);
  body_box(b, pose_b, box_b);
  // deeper than a quarter of the thinner box the axis of least overlap may be the far side's
  // (a box driven past a wall's middle in one long step would be pushed on through): the
  // samples then, both ways, with their own guard for deep points (see apply_contact_impulse)
  const double trusted = kTrustedDepth * std::min(defs_[a].thickness, defs_[b].thickness);
  BoxContact contact;
  if (!box_box_contact(box_a, box_b, margin, contact)) return true;
  if (contact.depth > trusted) return false;
  const Vec3 normal_b = pose_b.rotation.transpose() * contact.normal;
  for (int k = 0; k < contact.count; ++k) {
    const double depth = contact.points[k].depth;
    // (touching is not penetrating, as for the samples; within the margin outside: speculative)
    if (!(depth > kTouching || (margin > 0.0 && depth > -margin))) continue;
    const Vec3& on_a = contact.points[k].x;
    const Vec3 m = pose_a.apply_inverse(on_a);
    out.push_back({a, b, candidate_poses_[a].apply(m), contact.normal, -depth, m, s, true,
                   pose_b.apply_inverse(on_a + depth * contact.normal), normal_b});
  }
  return true;
}

// Body i's K at world point x, lever arm from its candidate centre of mass; zero for the
// ground and kinematic bodies
Mat3 World::body_impulse_matrix(int i, const Vec3& x) const {
  if (i == kGround || defs_[i].kinematic) return Mat3::Zero();
  return impulse_matrix(defs_[i].inverse_mass, inverse_inertia_[i], x - candidates_[i].x);
}

// K = K_a + K_b at the point; immovable bodies (ground, kinematic, frozen) contribute nothing
Mat3 World::pair_impulse_matrix(const Penetration& p) const {
  Mat3 K = Mat3::Zero();
  for (int i : {p.a, p.b}) {
    if (movable(i)) K += body_impulse_matrix(i, p.x);
  }
  return K;
}

// Body a takes J and body b takes -J, in linear and angular momentum; the stage's angular
// velocity follows (exactly for start-of-step velocities, to first order for average ones)
// and the candidate is marked stale
void World::exchange_impulse(const Penetration& p, const Vec3& J, ImpulseLog& log) {
  double sign = 1.0;
  for (int i : {p.a, p.b}) {
    if (movable(i)) {
      const Vec3 dl = sign * (p.x - candidates_[i].x).cross(J);
      states_[i].v += sign * defs_[i].inverse_mass * J;
      states_[i].l += dl;
      omega_[i] += inverse_inertia_[i] * dl;
      mark_stale(i, log);
      ++version_[i];
    }
    sign = -1.0;
  }
  ++log.impulses;
}

// ---------------------------------------------------------------------------------------
// Collisions (elastic): per pair and sweep, one impulse at the deepest non-separating point
// found in either direction, with start-of-step velocities; the impulse changes the
// candidates of both bodies at once. Pairs are visited in a different order every sweep
// (a deterministic shuffle seeded by the step and sweep numbers) so that no body is always
// served first.

bool World::apply_collision_impulse(const Penetration& p, double restitution, double friction, ImpulseLog& log) {
  const Vec3 v = point_velocity(p.a, p.x) - point_velocity(p.b, p.x);
  if (v.dot(p.n) >= -settings_.contact_tolerance) return false;
  exchange_impulse(p, coulomb_impulse(pair_impulse_matrix(p), p.n, v, restitution, friction), log);
  refresh_stale_candidates(log);
  return true;
}

// The point an impact strikes: the deepest sample alone, or, when other samples of the same
// body are as deep (within 0.1% of its depth) on the same face (normals within 8 degrees)
// and approaching too, the centroid of them all. A sample's depth is its approach speed
// times the time since it entered, so these entered within 0.1% of a substep of the
// deepest: the step cannot tell which came first, and they are struck together. A face landing flat
// (or an edge) is then hit at its middle, as a square hit must be, not at whichever corner
// round-off made deepest, which would spin the body and let friction throw it sideways.
Penetration World::struck_point(const std::vector<Penetration>& found, const Penetration& deepest) const {
  // an impact, not settling: slower than 1 m/s, or than gravity adds in two substeps, is a
  // stack settling, the contact stage's to finish; it keeps its single points (with the
  // centroid, the 15-row pyramid at 1/60 s substeps falls)
  const double approach = -(point_velocity(deepest.a, deepest.x) - point_velocity(deepest.b, deepest.x)).dot(deepest.n);
  if (approach <= std::max(kImpactSpeed, 2.0 * settings_.gravity.norm() * dt_)) return deepest;
  const double depth_tolerance = 1e-3 * -deepest.phi;
  Vec3 sum = Vec3::Zero();
  int count = 0;
  for (const Penetration& p : found) {
    if (p.a != deepest.a || p.phi > deepest.phi + depth_tolerance || p.n.dot(deepest.n) < 0.99) continue;
    if ((point_velocity(p.a, p.x) - point_velocity(p.b, p.x)).dot(p.n) >= -settings_.contact_tolerance) continue;
    sum += p.x;
    ++count;
  }
  if (count <= 1) return deepest;
  Penetration centre = deepest;
  centre.x = sum / count;
  // the centroid must itself approach (a spinning body's may not): else the deepest alone
  const Vec3 v = point_velocity(centre.a, centre.x) - point_velocity(centre.b, centre.x);
  return v.dot(centre.n) < -settings_.contact_tolerance ? centre : deepest;
}

namespace {

// Fisher-Yates with a fixed generator (splitmix64): the same order on every platform
void deterministic_shuffle(std::vector<int>& order, std::uint64_t seed) {
  auto next = [&seed] {
    std::uint64_t z = (seed += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  };
  for (std::size_t k = order.size(); k > 1; --k) std::swap(order[k - 1], order[next() % k]);
}

}  // namespace

void World::resolve_collisions(double dt) {
  begin_impulse_stage(dt, /*with_forces=*/true, /*average_velocities=*/false);
  // the first sweep runs the full narrow phase and remembers, per pair, every point found
  // inside the other body, and with speculative contacts those closer than the margin too
  // (see contact_margin): a box falling on a box that an impulse has just stopped enters it
  // within the sweeps; later sweeps re-test only those (a point farther out than the margin
  // at the first sweep stays outside)
  std::vector<std::vector<Penetration>>& inside = pair_scratch_;
  find_pair_penetrations(inside, settings_.speculative_contacts, /*reuse=*/false);
  // the bodies' versions now: those that change took an impulse (see find_pair_penetrations)
  std::vector<std::uint64_t>& before = collision_versions_;
  before.assign(version_.begin(), version_.end());
  // islands of the pairs with samples inside (the others have nothing to do), each swept on
  // its own and in parallel as in resolve_contacts: an island whose sweep applies no impulse
  // revisits no pair after it, so stopping it there gives the bits of the global sweeps
  IslandScratch& islands = islands_;
  islands.links.resize(pairs_.size());
  for (std::size_t k = 0; k < pairs_.size(); ++k) {
    islands.links[k] = inside[k].empty() ? std::array<int, 2>{-1, -1} : std::array<int, 2>{pairs_[k].a, pairs_[k].b};
  }
  find_islands(defs_, islands_);
  // each sweep's order of the island's pairs: all pairs shuffled, then taken island by island
  const int sweeps = settings_.collision_sweeps;
  const int m = islands.item_start[islands.count];
  std::vector<int>& order = islands.order;
  std::vector<int>& by_sweep = islands.by_sweep;  // (sweeps x m)
  order.resize(pairs_.size());
  by_sweep.resize(static_cast<std::size_t>(sweeps) * m);
  for (int sweep = 0; sweep < sweeps; ++sweep) {
    for (std::size_t k = 0; k < order.size(); ++k) order[k] = static_cast<int>(k);
    deterministic_shuffle(order, static_cast<std::uint64_t>(stats_.substeps) * 64 + sweep);
    islands.filled.assign(islands.item_start.begin(), islands.item_start.end() - 1);
    for (int index : order) {
      if (islands.of_item[index] >= 0) by_sweep[static_cast<std::size_t>(sweep) * m + islands.filled[islands.of_item[index]]++] = index;
    }
  }
  // sweep in which each body last took an impulse: after the first sweep only pairs with a
  // body that changed since the pair was last looked at can have anything new to offer
  std::vector<int>& changed = body_scratch_;
  changed.assign(body_count(), -1);
  auto changed_since = [&](int i, int sweep) { return i != kGround && changed[i] >= sweep - 1; };
  tbb::parallel_for(0, islands.count, [&](int island) {
    ImpulseLog& log = islands.logs[island];
    for (int sweep = 0; sweep < sweeps; ++sweep) {
      bool any = false;
      for (int c = islands.item_start[island]; c < islands.item_start[island + 1]; ++c) {
        const int index = by_sweep[static_cast<std::size_t>(sweep) * m + c];
        const BodyPair& pair = pairs_[index];
        std::vector<Penetration>& found = inside[index];
        if (sweep > 0 && !changed_since(pair.a, sweep) && !changed_since(pair.b, sweep)) continue;
        // the deepest point still inside and approaching faster than the contact tolerance
        const Penetration* deepest = nullptr;
        for (Penetration& p : found) {
          if (sweep > 0) refresh_contact(p);
          if (p.phi >= -kTouching) continue;
          const double approach = (point_velocity(p.a, p.x) - point_velocity(p.b, p.x)).dot(p.n);
          if (approach >= -settings_.contact_tolerance) continue;
          if (deepest == nullptr || p.phi < deepest->phi) deepest = &p;
        }
        if (deepest == nullptr) continue;
        const Penetration struck = struck_point(found, *deepest);
        if (!apply_collision_impulse(struck, pair.restitution, pair.friction, log)) continue;
        any = true;
        changed[pair.a] = sweep;
        if (pair.b != kGround) changed[pair.b] = sweep;
      }
      if (!any) break;
    }
  });
  collect_impulses();
  collided_.resize(body_count());
  for (int i = 0; i < body_count(); ++i) collided_[i] = version_[i] != before[i];
}

// Velocities: gravity on every dynamic body (no torque: it acts at the centre of mass)
void World::update_velocities(double dt) {
  for (int i = 0; i < body_count(); ++i) {
    if (!defs_[i].kinematic && !asleep_[i]) states_[i].v += dt * settings_.gravity;
  }
}

// ---------------------------------------------------------------------------------------
// Contacts (inelastic): the samples that penetrate at the candidates when the stage begins
// become the contact points of the whole stage (per pair, direction and normal the deepest
// and the three spanning the largest area, see reduce_to_four; deepest first within a pair); each sweep
// re-evaluates every contact at the bodies' current candidates with average velocities,
// until no impulse changes anything. (Points that only start to penetrate during the
// sweeps are left to the next step's collision stage, which catches them with forces.)
//
// Islands. Bodies connected through contacts (the ground and kinematic bodies, which no
// impulse moves, do not connect) form islands that share no movable body, so each island is
// swept on its own, in parallel, its contacts in their order. An island whose sweep applies
// no impulse is at its fixed point (every contact has seen its bodies as they are), so
// stopping it there gives exactly the bits of sweeping every contact until none changes, on
// any number of threads.

void World::resolve_contacts(double dt) {
  begin_impulse_stage(dt, /*with_forces=*/false, /*average_velocities=*/true);
  find_contacts();
  islands_.links.resize(contacts_.size());
  for (std::size_t k = 0; k < contacts_.size(); ++k) islands_.links[k] = {contacts_[k].point.a, contacts_[k].point.b};
  find_islands(defs_, islands_);
  const IslandScratch& islands = islands_;
  tbb::parallel_for(0, islands.count, [&](int k) {
    ImpulseLog& log = islands_.logs[k];
    for (int sweep = 0; sweep < settings_.contact_sweeps; ++sweep) {
      refresh_stale_candidates(log);
      bool any = false;
      for (int c = islands.item_start[k]; c < islands.item_start[k + 1]; ++c) {
        any |= apply_contact_impulse(contacts_[islands.items[c]], log);
      }
      if (!any) break;
    }
  });
  collect_impulses();
}



// Every pair's penetrating samples, both directions (pair order, then sample order); two boxes
// by their exact contact, once for the pair. Pairs are independent and read-only here, so they
// run in parallel; each writes only its own list, so the result is the same for any number of
// threads. With reuse (the contact stage), a pair whose bodies took no collision impulse keeps
// the list the collision stage found: its candidates are the same, bit for bit (x + dt (v + dt
// g) either way, the same rotation), and so are its margin (see contact_margin) and its one
// test; the narrow phase then runs once per step for most of a resting pile
void World::find_pair_penetrations(std::vector<std::vector<Penetration>>& out, bool speculative, bool reuse) {
  out.resize(pairs_.size());
  single_test_.resize(pairs_.size());
  tbb::parallel_for(std::size_t(0), pairs_.size(), [&](std::size_t k) {
    const int a = pairs_[k].a, b = pairs_[k].b;
    if (reuse && single_test_[k] && !collided_[a] && (b == kGround || !collided_[b])) return;
    out[k].clear();
    const double margin = speculative ? contact_margin(a, b) : 0.0;
    const long long tests = sweep_tests(a, b);  // (the same both ways)
    single_test_[k] = tests == 1;
    if (tests == 1 && box_pair_contact(a, b, 1.0, margin, out[k])) return;
    find_penetrations(a, b, margin, tests, out[k]);
    if (b != kGround) find_penetrations(b, a, margin, tests, out[k]);
  });
}

// Speculative contacts. A point of the contact stage is found at the candidates, which move
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
double World::contact_margin(int a, int b) const {
  // (not with cloths: a cloth between two bodies, or a body and the ground, is no part of
  // their contact, and closing the gap it fills pushes edges through it; shipped cloth_demo,
  // a box on a cloth over a sphere: body edges through the sheet at frames 26-33)
  if (!settings_.speculative_contacts || !cloths_.empty()) return 0.0;
  const double g = settings_.gravity.norm();
  double margin = settings_.penetration_slop + 2.0 * g * dt_ * dt_;
  double cap = std::numeric_limits<double>::infinity();
  for (int i : {a, b}) {
    if (i == kGround) continue;
    margin += 0.5 * dt_ * candidates_[i].v.norm();  // (the velocity over the step, gravity in)
    cap = std::min(cap, kTrustedDepth * defs_[i].thickness);
  }
  for (int i : {a, b}) {
    if (i != kGround && defs_[i].shape) cap = std::min(cap, 0.5 * defs_[i].shape->exterior_reach());
  }
  return std::min(margin, cap);
}

void World::find_contacts() {
  // per pair: each direction deepest first and reduced, then the pair's points deepest first
  std::vector<std::vector<Penetration>>& found = pair_scratch_;
  find_pair_penetrations(found, settings_.speculative_contacts, /*reuse=*/true);
  tbb::parallel_for(std::size_t(0), found.size(), [&](std::size_t k) {
    std::vector<Penetration>& points = found[k];
    const auto split = std::stable_partition(points.begin(), points.end(),
                                             [&](const Penetration& p) { return p.a == pairs_[k].a; });
    std::vector<Penetration> reverse(split, points.end());
    points.erase(split, points.end());
    for (std::vector<Penetration>* side : {&points, &reverse}) {
      std::stable_sort(side->begin(), side->end(), deeper);
      reduce_contact_points(*side);
    }
    points.insert(points.end(), reverse.begin(), reverse.end());
    std::stable_sort(points.begin(), points.end(), deeper);
  });
  contacts_.clear();
  for (std::size_t k = 0; k < found.size(); ++k) {
    for (const Penetration& p : found[k]) {
      contacts_.push_back({p, pairs_[k].friction, Vec3::Zero(), body_impulse_matrix(p.a, p.x),
                           body_impulse_matrix(p.b, p.x)});
      contacts_.back().apart = p.phi > 0.0;
    }
  }
}

// Moves a contact's sample with its body's candidate and takes b's normal there
// (at the fraction of the step where it was found: see the swept test)
void World::refresh_contact(Penetration& p) const {
  const Vec3& m = p.local;
  p.x = candidate_poses_[p.a].apply(m);
  if (p.b == kGround) {
    p.phi = p.x.y() - ground_->height;
    p.n = Vec3::UnitY();
  } else {
    const Pose pose_b = pose_at(p.b, p.s);
    const Vec3 x = p.s >= 1.0 ? p.x : pose_at(p.a, p.s).apply(m);
    if (p.crossing) {  // the two edges' points, carried by their bodies, along the normal
      p.n = pose_b.rotation * p.normal_b;
      p.phi = p.n.dot(x - pose_b.apply(p.local_b));
      return;
    }
    Vec3 n_local;
    p.phi = defs_[p.b].shape->phi_and_normal(pose_b.apply_inverse(x), n_local);
    p.n = pose_b.rotation * n_local;
  }
}

// Contact impulse at one contact point: one projected Gauss-Seidel update of the point's
// total impulse this stage (see contact_impulse_update); only the change is applied. A point
// deeper than penetration_slop asks for a separating speed of penetration_recovery times the
// excess depth per step (Baumgarte stabilization, capped): without it, the penetration left
// by a hard impact, or gathered while a tall stack first settles, would stay for good. A point
// whose bodies have not changed since it was last evaluated is skipped: the update would
// give the same answer, so converged parts of a pile cost nothing more.
bool World::apply_contact_impulse(ContactPoint& contact, ImpulseLog& log) {
  Penetration& p = contact.point;
  const bool a_moves = movable(p.a), b_moves = movable(p.b);
  if (!a_moves && !b_moves) return false;
  const std::uint64_t va = p.a == kGround ? 0 : version_[p.a], vb = p.b == kGround ? 0 : version_[p.b];
  if (va == contact.seen_a && vb == contact.seen_b) return false;
  refresh_contact(p);
  const Mat3 K = (a_moves ? contact.k_a : Mat3::Zero()) + (b_moves ? contact.k_b : Mat3::Zero());
  const Vec3 v = point_velocity(p.a, p.x) - point_velocity(p.b, p.x);
  // penetration recovery: deeper than the slop, ask for a small separating speed
  // deeper than a quarter of the thinner body, a level set's normal is its nearest face's,
  // not the way out: pushing there only spins the bodies up step after step (deep initial
  // overlaps), so such a point is held inelastically and not pushed
  const bool trusted = p.b == kGround || -p.phi <= kTrustedDepth * std::min(defs_[p.a].thickness, defs_[p.b].thickness);
  const double excess = trusted ? -p.phi - settings_.penetration_slop : 0.0;
  double target = excess > 0.0 ? std::min(settings_.penetration_recovery * excess / dt_,
                                          settings_.max_recovery_speed) : 0.0;
  // a speculative contact (see contact_margin): apart at the start of the step, the point may
  // close its gap and no more. (A point already inside when the stage began keeps the rule
  // above, which stops its approach even when its gap is not yet closed: between the samples
  // of a box, edges cross, and that extra hold keeps them apart)
  if (contact.apart) {
    const double gap = p.phi - dt_ * v.dot(p.n);
    if (gap > 0.0) target = -gap / dt_;
  }
  const Vec3 total = contact_impulse_update(K, p.n, v, contact.total, contact.friction, target);
  const Vec3 change = total - contact.total;
  if ((K * change).squaredNorm() <= settings_.contact_tolerance * settings_.contact_tolerance) {
    contact.seen_a = va;
    contact.seen_b = vb;
    return false;
  }
  contact.total = total;
  exchange_impulse(p, change, log);
  contact.seen_a = p.a == kGround ? 0 : version_[p.a];
  contact.seen_b = p.b == kGround ? 0 : version_[p.b];
  return true;
}

// ---------------------------------------------------------------------------------------
// Shock propagation (Guendelman et al. 2003, section 7): the iterations above need many
// sweeps to carry the weight of a tall stack down to the ground. Instead, the contact graph
// is levelled by breadth-first search from the bodies that touch the ground or a kinematic
// body (level 0); each level in turn is solved with every level below frozen (infinite
// mass), so the bottom of a stack is settled first and then holds everything above it.
// Bodies connected to nothing immovable keep the result of the sweeps.

// Levels by breadth-first search; shock_.order lists the connected bodies level by level
void World::assign_contact_levels() {
  const int n = body_count();
  std::fill(level_.begin(), level_.end(), -1);
  // the contact graph between dynamic bodies, as adjacency lists in one array
  std::vector<int>& start = shock_.neighbour_start;
  std::vector<int>& neighbours = shock_.neighbours;
  std::vector<int>& queue = shock_.order;
  start.assign(n + 1, 0);
  queue.clear();
  auto fixed = [&](int i) { return i == kGround || defs_[i].kinematic; };
  for (const ContactPoint& c : contacts_) {
    const int a = c.point.a, b = c.point.b;
    if (c.apart || fixed(a) || fixed(b)) continue;
    ++start[a + 1];
    ++start[b + 1];
  }
  std::partial_sum(start.begin(), start.end(), start.begin());
  neighbours.resize(start[n]);
  std::vector<int>& filled = body_scratch_;
  filled.assign(start.begin(), start.end() - 1);
  for (const ContactPoint& c : contacts_) {
    if (c.apart) continue;
    const int a = c.point.a, b = c.point.b;
    const bool a_fixed = fixed(a), b_fixed = fixed(b);
    if (b_fixed && !a_fixed && level_[a] < 0) { level_[a] = 0; queue.push_back(a); }
    if (a_fixed && !b_fixed && level_[b] < 0) { level_[b] = 0; queue.push_back(b); }
    if (!a_fixed && !b_fixed) {
      neighbours[filled[a]++] = b;
      neighbours[filled[b]++] = a;
    }
  }
  for (std::size_t head = 0; head < queue.size(); ++head) {
    const int i = queue[head];
    for (int k = start[i]; k < start[i + 1]; ++k) {
      const int j = neighbours[k];
      if (level_[j] < 0) {
        level_[j] = level_[i] + 1;
        queue.push_back(j);
      }
    }
  }
}

void World::propagate_shocks() {
  if (contacts_.empty()) return;
  // each body's velocities and fastest point speed |v| + |omega| r before the levels
  const int n = body_count();
  std::vector<Vec3>& v_before = shock_.v_before;
  std::vector<Vec3>& l_before = shock_.l_before;
  std::vector<double>& speed_before = shock_.speed_before;
  v_before.resize(n);
  l_before.resize(n);
  speed_before.resize(n);
  auto point_speed = [&](int i) {
    return states_[i].v.norm() + (inverse_inertia_[i] * states_[i].l).norm() * defs_[i].bounding_radius;
  };
  for (int i = 0; i < n; ++i) {
    v_before[i] = states_[i].v;
    l_before[i] = states_[i].l;
    speed_before[i] = point_speed(i);
  }
  assign_contact_levels();
  // the ground and kinematic bodies sit below level 0; bodies connected to neither
  // (level -1) keep the result of the sweeps. A contact's level is that of its upper body
  auto fixed = [&](int i) { return i == kGround || defs_[i].kinematic; };
  std::vector<int>& contact_level = shock_.contact_level;
  contact_level.resize(contacts_.size());
  for (std::size_t k = 0; k < contacts_.size(); ++k) {
    const int a = contacts_[k].point.a, b = contacts_[k].point.b;
    const bool connected = (fixed(a) || level_[a] >= 0) && (fixed(b) || level_[b] >= 0);
    contact_level[k] = connected ? std::max(fixed(a) ? -1 : level_[a], fixed(b) ? -1 : level_[b]) : -1;
  }
  // each island's levelled bodies, by level (shock_.order is sorted by level)
  IslandScratch& islands = islands_;
  std::vector<int>& body_start = islands.body_start;
  body_start.assign(islands.count + 1, 0);
  for (int i : shock_.order) ++body_start[islands.of_body[i] + 1];
  std::partial_sum(body_start.begin(), body_start.end(), body_start.begin());
  std::vector<int>& filled = body_scratch_;
  filled.assign(body_start.begin(), body_start.end() - 1);
  islands.bodies.resize(shock_.order.size());
  for (int i : shock_.order) islands.bodies[filled[islands.of_body[i]]++] = i;
  if (islands.by_level.size() < islands.logs.size()) islands.by_level.resize(islands.logs.size());
  // islands in parallel (see resolve_contacts), levels in turn within each: every body of
  // a level is frozen once the level is solved (a body of level l has a contact in level l)
  tbb::parallel_for(0, islands.count, [&](int k) {
    ImpulseLog& log = islands.logs[k];
    std::vector<int>& by_level = islands.by_level[k];
    by_level.clear();
    for (int c = islands.item_start[k]; c < islands.item_start[k + 1]; ++c) {
      if (contact_level[islands.items[c]] >= 0) by_level.push_back(islands.items[c]);
    }
    std::stable_sort(by_level.begin(), by_level.end(),
                     [&](int l, int r) { return contact_level[l] < contact_level[r]; });
    int next = body_start[k];
    for (std::size_t first = 0; first < by_level.size();) {
      const int level = contact_level[by_level[first]];
      std::size_t last = first;
      while (last < by_level.size() && contact_level[by_level[last]] == level) ++last;
      for (int sweep = 0; sweep < settings_.shock_sweeps; ++sweep) {
        refresh_stale_candidates(log);
        bool any = false;
        for (std::size_t c = first; c < last; ++c) any |= apply_contact_impulse(contacts_[by_level[c]], log);
        if (!any) break;
      }
      // freezing changes the K of every contact of the body: its version changes too
      for (; next < body_start[k + 1] && level_[islands.bodies[next]] == level; ++next) {
        frozen_[islands.bodies[next]] = 1;
        ++version_[islands.bodies[next]];
      }
      first = last;
    }
    refresh_stale_candidates(log);
  });
  for (int i : shock_.order) {
    if (!frozen_[i]) continue;
    ++version_[i];
    frozen_[i] = 0;
  }
  // Frozen levels are infinite masses, and where deep overlaps give a body contacts that
  // push opposite ways (the level set's normal deep inside points to the nearest face, not
  // the separating one) the levels can throw it off at any speed. Shock propagation only
  // settles what the sweeps found, so a body of a contact group whose fastest point leaves
  // it more than twice max_recovery_speed faster than it came in sends the whole group back
  // to the sweeps' velocities (momentum exchanged in equal pairs, speeds the recovery caps).
  // Twice: a level may add the recovery of the level below to its own (the top of a tower
  // settling at 1/60 s substeps gains 0.5 m/s and more, and must keep it to stand)
  std::vector<int>& group = shock_.group;
  reset_sets(group, n);
  auto root = [&](int i) { return set_root(group, i); };
  for (const ContactPoint& c : contacts_) {
    if (!c.apart && c.point.b != kGround) group[root(c.point.a)] = root(c.point.b);
  }
  std::vector<char>& thrown = shock_.thrown;
  thrown.assign(n, 0);
  for (int i = 0; i < n; ++i) {
    if (movable(i) && point_speed(i) > speed_before[i] + 2.0 * settings_.max_recovery_speed) {
      thrown[root(i)] = 1;
    }
  }
  for (int i = 0; i < n; ++i) {
    if (!thrown[root(i)] || !movable(i)) continue;
    states_[i].v = v_before[i];
    states_[i].l = l_before[i];
    mark_stale(i, log_);
    ++version_[i];
  }
  refresh_stale_candidates(log_);
  collect_impulses();
}

// The impulses of the stage so far into the statistics (the logs' counts are summed after
// the parallel part, so the total is the same on any number of threads)
void World::collect_impulses() {
  for (int k = 0; k < islands_.count; ++k) {
    stats_.impulses += islands_.logs[k].impulses;
    islands_.logs[k].impulses = 0;
  }
  stats_.impulses += log_.impulses;
  log_.impulses = 0;
}

// Positions: x += dt v and the torque-free rotation with the final L (what the contact
// stage's average velocities assumed)
void World::update_positions(double dt) {
  dt_ = dt;
  candidates_with_forces_ = false;
  average_velocities_ = false;
  tbb::parallel_for(0, body_count(), [&](int i) {
    if (asleep_[i]) return;
    update_candidate(i);
    states_[i].x = candidates_[i].x;
    states_[i].q = candidates_[i].q;
  });
  log_.stale.clear();
}

}  // namespace simbake
