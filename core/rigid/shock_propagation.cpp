// Shock propagation (Guendelman et al. 2003, section 7): the contact stage needs many
// sweeps to carry the weight of a tall stack down to the ground. Instead, the contact graph
// is levelled by breadth-first search from the bodies that touch the ground or a kinematic
// body (level 0); each level in turn is solved with every level below frozen (infinite
// mass), so the bottom of a stack is settled first and then holds everything above it.
// Bodies connected to nothing immovable keep the result of the sweeps.
#include "rigid/shock_propagation.h"

#include "rigid/contacts.h"
#include "rigid/impulse_stage.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <numeric>

namespace simbake {

namespace {

// Body i's fastest point speed |v| + |omega| r (m/s)
double fastest_point_speed(const RigidModel& model, const RigidData& data, const RigidScratch& scratch, int i) {
  return data.v[i].norm() + (scratch.inverse_inertia[i] * data.l[i]).norm() * model.defs[i].bounding_radius;
}

// Levels by breadth-first search; scratch.shock.order lists the connected bodies level by level.
// Speculative contacts (apart when the stage began) level their bodies too: a box falling onto
// a stack is held, within the stage, only by its speculative points, and left out of the levels
// it would keep the sweeps' unconverged velocities while the levels below it change under it
// (it then closes its gap and goes on into the box below)
void assign_contact_levels(const RigidModel& model, RigidScratch& scratch) {
  const int n = model.body_count();
  std::fill(scratch.level.begin(), scratch.level.end(), -1);
  // the contact graph between dynamic bodies, as adjacency lists in one array
  std::vector<int>& start = scratch.shock.neighbour_start;
  std::vector<int>& neighbours = scratch.shock.neighbours;
  std::vector<int>& queue = scratch.shock.order;
  start.assign(n + 1, 0);
  queue.clear();
  auto fixed = [&](int i) { return i == kGround || model.defs[i].kinematic; };
  for (const ContactPoint& c : scratch.contacts) {
    const int a = c.point.a, b = c.point.b;
    if (fixed(a) || fixed(b)) continue;
    ++start[a + 1];
    ++start[b + 1];
  }
  std::partial_sum(start.begin(), start.end(), start.begin());
  neighbours.resize(start[n]);
  std::vector<int>& filled = scratch.body_scratch;
  filled.assign(start.begin(), start.end() - 1);
  for (const ContactPoint& c : scratch.contacts) {
    const int a = c.point.a, b = c.point.b;
    const bool a_fixed = fixed(a), b_fixed = fixed(b);
    if (b_fixed && !a_fixed && scratch.level[a] < 0) { scratch.level[a] = 0; queue.push_back(a); }
    if (a_fixed && !b_fixed && scratch.level[b] < 0) { scratch.level[b] = 0; queue.push_back(b); }
    if (!a_fixed && !b_fixed) {
      neighbours[filled[a]++] = b;
      neighbours[filled[b]++] = a;
    }
  }
  for (std::size_t head = 0; head < queue.size(); ++head) {
    const int i = queue[head];
    for (int k = start[i]; k < start[i + 1]; ++k) {
      const int j = neighbours[k];
      if (scratch.level[j] < 0) {
        scratch.level[j] = scratch.level[i] + 1;
        queue.push_back(j);
      }
    }
  }
}

// Each contact's level, that of its upper body, and each island's levelled bodies by level
void order_levels(const RigidModel& model, RigidScratch& scratch) {
  // the ground and kinematic bodies sit below level 0; bodies connected to neither
  // (level -1) keep the result of the sweeps. A contact's level is that of its upper body
  auto fixed = [&](int i) { return i == kGround || model.defs[i].kinematic; };
  std::vector<int>& contact_level = scratch.shock.contact_level;
  contact_level.resize(scratch.contacts.size());
  for (std::size_t k = 0; k < scratch.contacts.size(); ++k) {
    const int a = scratch.contacts[k].point.a, b = scratch.contacts[k].point.b;
    const bool connected = (fixed(a) || scratch.level[a] >= 0) && (fixed(b) || scratch.level[b] >= 0);
    contact_level[k] = connected ? std::max(fixed(a) ? -1 : scratch.level[a], fixed(b) ? -1 : scratch.level[b]) : -1;
  }
  // each island's levelled bodies, by level (scratch.shock.order is sorted by level)
  IslandScratch& islands = scratch.islands;
  std::vector<int>& body_start = islands.body_start;
  body_start.assign(islands.count + 1, 0);
  for (int i : scratch.shock.order) ++body_start[islands.of_body[i] + 1];
  std::partial_sum(body_start.begin(), body_start.end(), body_start.begin());
  std::vector<int>& filled = scratch.body_scratch;
  filled.assign(body_start.begin(), body_start.end() - 1);
  islands.bodies.resize(scratch.shock.order.size());
  for (int i : scratch.shock.order) islands.bodies[filled[islands.of_body[i]]++] = i;
  if (islands.by_level.size() < islands.logs.size()) islands.by_level.resize(islands.logs.size());
}

// The levels of each island solved in turn (islands in parallel), each level's bodies frozen
// once it is solved, then all unfrozen
void solve_levels(const RigidModel& model, RigidData& data, RigidScratch& scratch, const WorldSettings& settings) {
  IslandScratch& islands = scratch.islands;
  const std::vector<int>& body_start = islands.body_start;
  const std::vector<int>& contact_level = scratch.shock.contact_level;
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
      for (int sweep = 0; sweep < settings.shock_sweeps; ++sweep) {
        refresh_stale_candidates(model, data, scratch, settings, log);
        bool any = false;
        for (std::size_t c = first; c < last; ++c) any |= apply_contact_impulse(model, data, scratch, settings, scratch.contacts[by_level[c]], log);
        if (!any) break;
      }
      // freezing changes the K of every contact of the body: its version changes too
      for (; next < body_start[k + 1] && scratch.level[islands.bodies[next]] == level; ++next) {
        scratch.frozen[islands.bodies[next]] = 1;
        ++scratch.version[islands.bodies[next]];
      }
      first = last;
    }
    refresh_stale_candidates(model, data, scratch, settings, log);
  });
  for (int i : scratch.shock.order) {
    if (!scratch.frozen[i]) continue;
    ++scratch.version[i];
    scratch.frozen[i] = 0;
  }
}

// Groups thrown off by the levels sent back to the sweeps' velocities
void restore_thrown_groups(const RigidModel& model, RigidData& data, RigidScratch& scratch, const WorldSettings& settings) {
  const int n = model.body_count();
  const std::vector<Vec3>& v_before = scratch.shock.v_before;
  const std::vector<Vec3>& l_before = scratch.shock.l_before;
  const std::vector<double>& speed_before = scratch.shock.speed_before;
  // Frozen levels are infinite masses, and where deep overlaps give a body contacts that
  // push opposite ways (the level set's normal deep inside points to the nearest face, not
  // the separating one) the levels can throw it off at any speed. Shock propagation only
  // settles what the sweeps found, so a body of a contact group whose fastest point leaves
  // it more than twice max_recovery_speed faster than it came in sends the whole group back
  // to the sweeps' velocities (momentum exchanged in equal pairs, speeds the recovery caps).
  // Twice: a level may add the recovery of the level below to its own (the top of a tower
  // settling at long substeps gains about the recovery speed, and must keep it to stand)
  std::vector<int>& group = scratch.shock.group;
  reset_sets(group, n);
  auto root = [&](int i) { return set_root(group, i); };
  for (const ContactPoint& c : scratch.contacts) {
    if (!c.apart && c.point.b != kGround) group[root(c.point.a)] = root(c.point.b);
  }
  std::vector<char>& thrown = scratch.shock.thrown;
  thrown.assign(n, 0);
  for (int i = 0; i < n; ++i) {
    if (movable(model, scratch, i) && fastest_point_speed(model, data, scratch, i) > speed_before[i] + 2.0 * settings.max_recovery_speed) {
      thrown[root(i)] = 1;
    }
  }
  for (int i = 0; i < n; ++i) {
    if (!thrown[root(i)] || !movable(model, scratch, i)) continue;
    data.v[i] = v_before[i];
    data.l[i] = l_before[i];
    mark_stale(scratch, i, scratch.log);
    ++scratch.version[i];
  }
  refresh_stale_candidates(model, data, scratch, settings, scratch.log);
}

}  // namespace

void propagate_shocks(const RigidModel& model, RigidData& data, RigidScratch& scratch, const WorldSettings& settings) {
  if (scratch.contacts.empty()) return;
  // each body's velocities and fastest point speed |v| + |omega| r before the levels
  const int n = model.body_count();
  std::vector<Vec3>& v_before = scratch.shock.v_before;
  std::vector<Vec3>& l_before = scratch.shock.l_before;
  std::vector<double>& speed_before = scratch.shock.speed_before;
  v_before.resize(n);
  l_before.resize(n);
  speed_before.resize(n);
  for (int i = 0; i < n; ++i) {
    v_before[i] = data.v[i];
    l_before[i] = data.l[i];
    speed_before[i] = fastest_point_speed(model, data, scratch, i);
  }
  assign_contact_levels(model, scratch);
  order_levels(model, scratch);
  solve_levels(model, data, scratch, settings);
  restore_thrown_groups(model, data, scratch, settings);
  collect_impulses(scratch);
}

}  // namespace simbake
