// The collision stage (elastic), after Guendelman, Bridson and Fedkiw 2003 and the seed notes
// (the candidates and point velocities it works with are described in impulse_stage.h): per
// pair and sweep, one impulse at the deepest non-separating point found in either direction, with start-of-step velocities; the impulse changes the
// candidates of both bodies at once. Pairs are visited in a different order every sweep
// (a deterministic shuffle seeded by the step and sweep numbers) so that no body is always
// served first.
#include "rigid/collisions.h"

#include "rigid/impulse.h"
#include "rigid/impulse_stage.h"
#include "rigid/narrow_phase.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cstdint>

namespace simbake {

namespace {

constexpr double kImpactSpeed = 1.0;    // (m/s) slower approaches are settling, not impacts

// One Coulomb impulse with restitution at p, if its bodies approach there
bool apply_collision_impulse(const RigidModel& model, RigidData& data, RigidScratch& scratch, const WorldSettings& settings,
                             const Penetration& p, double restitution, double friction, ImpulseLog& log) {
  const Vec3 v = point_velocity(data, scratch, p.a, p.x) - point_velocity(data, scratch, p.b, p.x);
  if (v.dot(p.n) >= -settings.contact_tolerance) return false;
  exchange_impulse(model, data, scratch, p, coulomb_impulse(pair_impulse_matrix(model, scratch, p), p.n, v, restitution, friction), log);
  refresh_stale_candidates(model, data, scratch, settings, log);
  return true;
}

// The point an impact strikes: the deepest sample alone, or, when other samples of the same
// body are as deep (within 0.1% of its depth) on the same face (normals within 8 degrees)
// and approaching too, the centroid of them all. A sample's depth is its approach speed
// times the time since it entered, so these entered within 0.1% of a substep of the
// deepest: the step cannot tell which came first, and they are struck together. A face landing flat
// (or an edge) is then hit at its middle, as a square hit must be, not at whichever corner
// round-off made deepest, which would spin the body and let friction throw it sideways.
Penetration struck_point(const RigidData& data, const RigidScratch& scratch, const WorldSettings& settings,
                         const std::vector<Penetration>& found, const Penetration& deepest) {
  // an impact, not settling: slower than 1 m/s, or than gravity adds in two substeps, is a
  // stack settling, the contact stage's to finish; it keeps its single points (with the
  // centroid, a tall pyramid at long substeps falls)
  const double approach = -(point_velocity(data, scratch, deepest.a, deepest.x) - point_velocity(data, scratch, deepest.b, deepest.x)).dot(deepest.n);
  if (approach <= std::max(kImpactSpeed, 2.0 * settings.gravity.norm() * scratch.dt)) return deepest;
  const double depth_tolerance = 1e-3 * -deepest.phi;
  Vec3 sum = Vec3::Zero();
  int count = 0;
  for (const Penetration& p : found) {
    if (p.a != deepest.a || p.phi > deepest.phi + depth_tolerance || p.n.dot(deepest.n) < 0.99) continue;
    if ((point_velocity(data, scratch, p.a, p.x) - point_velocity(data, scratch, p.b, p.x)).dot(p.n) >= -settings.contact_tolerance) continue;
    sum += p.x;
    ++count;
  }
  if (count <= 1) return deepest;
  Penetration centre = deepest;
  centre.x = sum / count;
  // the centroid must itself approach (a spinning body's may not): else the deepest alone
  const Vec3 v = point_velocity(data, scratch, centre.a, centre.x) - point_velocity(data, scratch, centre.b, centre.x);
  return v.dot(centre.n) < -settings.contact_tolerance ? centre : deepest;
}

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

void resolve_collisions(const RigidModel& model, RigidData& data, RigidScratch& scratch, const WorldSettings& settings,
                        double dt, long long step) {
  begin_impulse_stage(model, data, scratch, settings, dt, /*with_forces=*/true, /*average_velocities=*/false);
  // the first sweep runs the full narrow phase and remembers, per pair, every point found
  // inside the other body, and with speculative contacts those closer than the margin too
  // (see contact_margin): a box falling on a box that an impulse has just stopped enters it
  // within the sweeps; later sweeps re-test only those (a point farther out than the margin
  // at the first sweep stays outside)
  std::vector<std::vector<Penetration>>& inside = scratch.pair_points;
  find_pair_penetrations(model, data, scratch, settings, settings.speculative_contacts, /*reuse=*/false);
  // the bodies' versions now: those that change took an impulse (see find_pair_penetrations)
  std::vector<std::uint64_t>& before = scratch.collision_versions;
  before.assign(scratch.version.begin(), scratch.version.end());
  // islands of the pairs with samples inside (the others have nothing to do), each swept on
  // its own and in parallel as in resolve_contacts: an island whose sweep applies no impulse
  // revisits no pair after it, so stopping it there gives the bits of the global sweeps
  IslandScratch& islands = scratch.islands;
  islands.links.resize(scratch.pairs.size());
  for (std::size_t k = 0; k < scratch.pairs.size(); ++k) {
    islands.links[k] = inside[k].empty() ? std::array<int, 2>{-1, -1} : std::array<int, 2>{scratch.pairs[k].a, scratch.pairs[k].b};
  }
  find_islands(model.defs, islands);
  // each sweep's order of the island's pairs: all pairs shuffled, then taken island by island
  const int sweeps = settings.collision_sweeps;
  const int m = islands.item_start[islands.count];
  std::vector<int>& order = islands.order;
  std::vector<int>& by_sweep = islands.by_sweep;  // (sweeps x m)
  order.resize(scratch.pairs.size());
  by_sweep.resize(static_cast<std::size_t>(sweeps) * m);
  for (int sweep = 0; sweep < sweeps; ++sweep) {
    for (std::size_t k = 0; k < order.size(); ++k) order[k] = static_cast<int>(k);
    deterministic_shuffle(order, static_cast<std::uint64_t>(step) * 64 + sweep);
    islands.filled.assign(islands.item_start.begin(), islands.item_start.end() - 1);
    for (int index : order) {
      if (islands.of_item[index] >= 0) by_sweep[static_cast<std::size_t>(sweep) * m + islands.filled[islands.of_item[index]]++] = index;
    }
  }
  // sweep in which each body last took an impulse: after the first sweep only pairs with a
  // body that changed since the pair was last looked at can have anything new to offer
  std::vector<int>& changed = scratch.body_scratch;
  changed.assign(model.body_count(), -1);
  auto changed_since = [&](int i, int sweep) { return i != kGround && changed[i] >= sweep - 1; };
  tbb::parallel_for(0, islands.count, [&](int island) {
    ImpulseLog& log = islands.logs[island];
    for (int sweep = 0; sweep < sweeps; ++sweep) {
      bool any = false;
      for (int c = islands.item_start[island]; c < islands.item_start[island + 1]; ++c) {
        const int index = by_sweep[static_cast<std::size_t>(sweep) * m + c];
        const BodyPair& pair = scratch.pairs[index];
        std::vector<Penetration>& found = inside[index];
        if (sweep > 0 && !changed_since(pair.a, sweep) && !changed_since(pair.b, sweep)) continue;
        // the deepest point still inside and approaching faster than the contact tolerance
        const Penetration* deepest = nullptr;
        for (Penetration& p : found) {
          if (sweep > 0) refresh_contact(model, data, scratch, p);
          if (p.phi >= -kTouching) continue;
          const double approach = (point_velocity(data, scratch, p.a, p.x) - point_velocity(data, scratch, p.b, p.x)).dot(p.n);
          if (approach >= -settings.contact_tolerance) continue;
          if (deepest == nullptr || p.phi < deepest->phi) deepest = &p;
        }
        if (deepest == nullptr) continue;
        const Penetration struck = struck_point(data, scratch, settings, found, *deepest);
        if (!apply_collision_impulse(model, data, scratch, settings, struck, pair.restitution, pair.friction, log)) continue;
        any = true;
        changed[pair.a] = sweep;
        if (pair.b != kGround) changed[pair.b] = sweep;
      }
      if (!any) break;
    }
  });
  collect_impulses(scratch);
  scratch.collided.resize(model.body_count());
  for (int i = 0; i < model.body_count(); ++i) scratch.collided[i] = scratch.version[i] != before[i];
}

}  // namespace simbake
