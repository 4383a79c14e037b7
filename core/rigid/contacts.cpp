// The contact stage (inelastic): the samples that penetrate at the candidates when the stage begins
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
#include "rigid/contacts.h"

#include "rigid/impulse.h"
#include "rigid/impulse_stage.h"
#include "rigid/narrow_phase.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstdint>

namespace simbake {

namespace {

// The contact points of the stage: per pair, each direction deepest first and reduced, then
// the pair's points deepest first
void find_contacts(const RigidModel& model, const RigidData& data, RigidScratch& scratch, const WorldSettings& settings) {
  std::vector<std::vector<Penetration>>& found = scratch.pair_points;
  find_pair_penetrations(model, data, scratch, settings, settings.speculative_contacts, /*reuse=*/true);
  tbb::parallel_for(std::size_t(0), found.size(), [&](std::size_t k) {
    std::vector<Penetration>& points = found[k];
    const int a = scratch.pairs[k].a;
    // (all of a's, as two boxes' exact contact is: no second list)
    if (std::all_of(points.begin(), points.end(), [&](const Penetration& p) { return p.a == a; })) {
      sort_deepest_first(points);
      reduce_contact_points(points);
      sort_deepest_first(points);
      return;
    }
    const auto split = std::stable_partition(points.begin(), points.end(), [&](const Penetration& p) { return p.a == a; });
    std::vector<Penetration> reverse(split, points.end());
    points.erase(split, points.end());
    for (std::vector<Penetration>* side : {&points, &reverse}) {
      sort_deepest_first(*side);
      reduce_contact_points(*side);
    }
    points.insert(points.end(), reverse.begin(), reverse.end());
    sort_deepest_first(points);
  });
  scratch.contacts.clear();
  for (std::size_t k = 0; k < found.size(); ++k) {
    for (const Penetration& p : found[k]) {
      scratch.contacts.push_back({p, scratch.pairs[k].friction, Vec3::Zero(), body_impulse_matrix(model, scratch, p.a, p.x),
                           body_impulse_matrix(model, scratch, p.b, p.x)});
      scratch.contacts.back().apart = p.phi > 0.0;
    }
  }
}

}  // namespace

void resolve_contacts(const RigidModel& model, RigidData& data, RigidScratch& scratch, const WorldSettings& settings,
                      double dt) {
  begin_impulse_stage(model, data, scratch, settings, dt, /*with_forces=*/false, /*average_velocities=*/true);
  find_contacts(model, data, scratch, settings);
  scratch.islands.links.resize(scratch.contacts.size());
  for (std::size_t k = 0; k < scratch.contacts.size(); ++k) scratch.islands.links[k] = {scratch.contacts[k].point.a, scratch.contacts[k].point.b};
  find_islands(model.defs, scratch.islands);
  const IslandScratch& islands = scratch.islands;
  tbb::parallel_for(0, islands.count, [&](int k) {
    ImpulseLog& log = scratch.islands.logs[k];
    for (int sweep = 0; sweep < settings.contact_sweeps; ++sweep) {
      refresh_stale_candidates(model, data, scratch, settings, log);
      bool any = false;
      for (int c = islands.item_start[k]; c < islands.item_start[k + 1]; ++c) {
        any |= apply_contact_impulse(model, data, scratch, settings, scratch.contacts[islands.items[c]], log);
      }
      if (!any) break;
    }
  });
  collect_impulses(scratch);
}

// Contact impulse at one contact point: one projected Gauss-Seidel update of the point's
// total impulse this stage (see contact_impulse_update); only the change is applied. A point
// deeper than penetration_slop asks for a separating speed of penetration_recovery times the
// excess depth per step (Baumgarte stabilization, capped): without it, the penetration left
// by a hard impact, or gathered while a tall stack first settles, would stay for good. A point
// whose bodies have not changed since it was last evaluated is skipped: the update would
// give the same answer, so converged parts of a pile cost nothing more.
bool apply_contact_impulse(const RigidModel& model, RigidData& data, RigidScratch& scratch,
                           const WorldSettings& settings, ContactPoint& contact, ImpulseLog& log) {
  Penetration& p = contact.point;
  const bool a_moves = movable(model, scratch, p.a), b_moves = movable(model, scratch, p.b);
  if (!a_moves && !b_moves) return false;
  const std::uint64_t va = p.a == kGround ? 0 : scratch.version[p.a], vb = p.b == kGround ? 0 : scratch.version[p.b];
  if (va == contact.seen_a && vb == contact.seen_b) return false;
  refresh_contact(model, data, scratch, p);
  const Mat3 K = (a_moves ? contact.k_a : Mat3::Zero()) + (b_moves ? contact.k_b : Mat3::Zero());
  const Vec3 v = point_velocity(data, scratch, p.a, p.x) - point_velocity(data, scratch, p.b, p.x);
  // penetration recovery: deeper than the slop, ask for a small separating speed
  // deeper than a quarter of the thinner body, a level set's normal is its nearest face's,
  // not the way out: pushing there only spins the bodies up step after step (deep initial
  // overlaps), so such a point is held inelastically and not pushed
  const bool trusted = p.b == kGround || -p.phi <= kTrustedDepth * std::min(model.defs[p.a].thickness, model.defs[p.b].thickness);
  const double excess = trusted ? -p.phi - settings.penetration_slop : 0.0;
  double target = excess > 0.0 ? std::min(settings.penetration_recovery * excess / scratch.dt,
                                          settings.max_recovery_speed) : 0.0;
  // a speculative contact (see contact_margin): apart at the start of the step, the point may
  // close its gap and no more. (A point already inside when the stage began keeps the rule
  // above, which stops its approach even when its gap is not yet closed: between the samples
  // of a box, edges cross, and that extra hold keeps them apart)
  if (contact.apart) {
    const double gap = p.phi - scratch.dt * v.dot(p.n);
    if (gap > 0.0) target = -gap / scratch.dt;
  }
  const Vec3 total = contact_impulse_update(K, p.n, v, contact.total, contact.friction, target);
  const Vec3 change = total - contact.total;
  if ((K * change).squaredNorm() <= settings.contact_tolerance * settings.contact_tolerance) {
    contact.seen_a = va;
    contact.seen_b = vb;
    return false;
  }
  contact.total = total;
  exchange_impulse(model, data, scratch, p, change, log);
  contact.seen_a = p.a == kGround ? 0 : scratch.version[p.a];
  contact.seen_b = p.b == kGround ? 0 : scratch.version[p.b];
  return true;
}

}  // namespace simbake
