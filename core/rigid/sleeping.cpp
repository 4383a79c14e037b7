// Sleeping. Bodies are grouped into islands connected through this step's contact points
// and their enabled joints (the ground and kinematic bodies do not connect). A body is at rest while none of its points
// has strayed further than sleep_speed * sleep_time / 2 from where it was when its rest began
// (so the bottom of a loaded pile, whose velocities flicker at the solver's tolerance without
// going anywhere, counts as resting). When every body of an island has rested for sleep_time
// seconds the island sleeps: its velocities are zeroed and every stage skips it, until an
// awake body touches it (rigid/broad_phase.cpp) or a cloth's contact does.
#include "rigid/sleeping.h"

#include <algorithm>

namespace simbake {

namespace {

int find_island(RigidData& data, int i) {
  std::vector<int>& island = data.island;
  while (island[i] != i) i = island[i] = island[island[i]];
  return i;
}

}  // namespace

void wake_island(const RigidModel& model, RigidData& data, int i) {
  const int root = data.island[i];
  for (int j = 0; j < model.body_count(); ++j) {
    if (data.asleep[j] && data.island[j] == root) {
      data.asleep[j] = 0;
      data.rest_time[j] = 0.0;
    }
  }
}

void update_sleeping(const RigidModel& model, RigidData& data, const RigidScratch& scratch,
                     const WorldSettings& settings, double dt) {
  if (settings.sleep_time <= 0.0) return;
  const int n = model.body_count();
  const auto find = [&](int i) { return find_island(data, i); };
  // islands of awake dynamic bodies through this step's contacts (union-find, smaller root wins)
  for (int i = 0; i < n; ++i) {
    if (!data.asleep[i]) data.island[i] = i;
  }
  for (const ContactPoint& contact : scratch.contacts) {
    const int a = contact.point.a, b = contact.point.b;
    if (contact.apart || b == kGround || model.defs[a].kinematic || model.defs[b].kinematic) continue;
    const int ra = find(a), rb = find(b);
    if (ra != rb) data.island[std::max(ra, rb)] = std::min(ra, rb);
  }
  // and through the enabled joints between dynamic bodies
  for (int j = 0; j < static_cast<int>(model.joints.size()); ++j) {
    const int a = model.joints[j].body0, b = model.joints[j].body1;
    if (!data.joints.enabled[j] || a < 0 || b < 0 || model.defs[a].kinematic || model.defs[b].kinematic) continue;
    const int ra = find(a), rb = find(b);
    if (ra != rb) data.island[std::max(ra, rb)] = std::min(ra, rb);
  }
  // rest time of each awake body; an island is ready when all of its bodies are
  std::vector<char> ready(n, 1);
  const double allowed = 0.5 * settings.sleep_speed * settings.sleep_time;  // (m)
  for (int i = 0; i < n; ++i) {
    if (model.defs[i].kinematic || data.asleep[i]) continue;
    const double radius = model.defs[i].bounding_radius;
    const double speed = data.v[i].norm() + angular_velocity(model.defs[i], data.q[i], data.l[i]).norm() * radius;
    const double strayed = (data.x[i] - data.rest_x[i]).norm() + data.q[i].angularDistance(data.rest_q[i]) * radius;
    if ((speed >= settings.sleep_speed && strayed > allowed) || data.rest_time[i] == 0.0) {
      data.rest_time[i] = dt;
      data.rest_x[i] = data.x[i];
      data.rest_q[i] = data.q[i];
    } else {
      data.rest_time[i] += dt;
    }
    if (data.rest_time[i] < settings.sleep_time) ready[find(i)] = 0;
  }
  // still pushing out of a deep overlap (deeper than ten times the slop) keeps an island awake,
  // as does touching a moving kinematic body
  for (const ContactPoint& c : scratch.contacts) {
    if (-c.point.phi <= 10.0 * settings.penetration_slop) continue;
    for (int i : {c.point.a, c.point.b}) {
      if (i != kGround && !model.defs[i].kinematic) ready[find(i)] = 0;
    }
  }
  for (const ContactPoint& c : scratch.contacts) {
    if (moving_kinematic(model, data, c.point.a) && c.point.b != kGround) ready[find(c.point.b)] = 0;
    if (c.point.b != kGround && moving_kinematic(model, data, c.point.b)) ready[find(c.point.a)] = 0;
  }
  for (int i = 0; i < n; ++i) {
    if (model.defs[i].kinematic || data.asleep[i]) continue;
    data.island[i] = find(i);
    if (!ready[data.island[i]]) continue;
    data.asleep[i] = 1;
    data.v[i] = Vec3::Zero();
    data.l[i] = Vec3::Zero();
  }
}

int sleeping_count(const RigidData& data) {
  return static_cast<int>(std::count(data.asleep.begin(), data.asleep.end(), 1));
}

}  // namespace simbake
