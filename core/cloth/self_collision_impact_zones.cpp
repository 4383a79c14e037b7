// Self-collision's rigid impact zones (Provot 1997; the last of the three parts at the top of
// self_collision.h): the vertices of the collisions left merged into zones, each moved
// rigidly, until nothing collides.
#include "cloth/self_collision.h"

#include "cloth/self_collision_detail.h"

#include <Eigen/Dense>

#include <numeric>

namespace simbake {

using namespace self_collision_detail;

namespace {

// A zone's vertices given one rigid motion, that of the zone's momentum and angular momentum
// about its centre of mass, with `impulse` (n x 3, N s, if any) added to its vertices' own. A
// zone holding vertices of infinite mass moves as they do: those of one obstacle (obstacle_of
// >= 0) give the zone that obstacle's motion (motions[obstacle]), which carries the zone and
// the obstacle by one invertible affine map, so that nothing in the zone passes through the
// obstacle; attached cloth vertices give it their attachment's (settings.attachment_motion);
// a pinned cloth vertex, or two of these, hold the zone still, and so does the
// surface under it where the obstacle would carry one of its vertices into that surface
// faster than `sink` (m/s): the obstacle then passes through the cloth (returns true).
// Vertices of infinite mass keep their own velocities.
bool move_rigidly(const std::vector<int>& zone, const Points& x, Points& v, const Eigen::VectorXd& inverse_mass,
                  const Points* impulse, const std::vector<int>& obstacle_of, int cloth_vertices,
                  const SelfCollisionSettings& settings, double sink) {
  const std::vector<ObstacleMotion>* motions = settings.obstacle_motion;
  const std::vector<Vec3>* support = settings.support;
  const ObstacleMotion* attachment = settings.attached ? settings.attachment_motion : nullptr;
  const ObstacleMotion* motion = nullptr;  // the one motion the zone's vertices of infinite mass share
  bool held = false, still = false;        // still: a pinned vertex, or two motions
  for (int i : zone) {
    if (inverse_mass[i] > 0.0) continue;
    const ObstacleMotion* own = nullptr;
    if (i >= cloth_vertices) {
      if (motions) own = &(*motions)[obstacle_of[i - cloth_vertices]];
    } else if (attachment && (*settings.attached)[i]) {
      own = attachment;
    }
    if (!own || (held && own != motion)) still = true;
    motion = own;
    held = true;
  }
  if (held) {
    if (still) motion = nullptr;
    // An obstacle that would carry a vertex of the zone into the still surface it rests on (a
    // keyed box pressing the cloth into the ground) cannot be followed: the cloth cannot be in
    // two places. The surface holds the zone, as a pin would, and the obstacle passes through
    // the cloth there (from the next step on, its contacts and self-collision leave the
    // vertices inside it alone: cloth_body_contact.cpp, SelfCollisionSettings::yielding).
    // Followed, the zone would go under the ground with the box, the edges from it to the
    // cloth the ground holds would stretch by the box's travel every step, and the candidate
    // pairs and the step's work with them would grow without bound
    bool yields = false;
    for (int i : zone) {
      if (!motion || !support || inverse_mass[i] <= 0.0 || !((*support)[i].squaredNorm() > 0.0)) continue;
      yields = yields || Vec3(motion->A * row(x, i) + motion->c).dot((*support)[i].normalized()) < -sink;
    }
    if (yields) motion = nullptr;
    for (int i : zone) {
      if (inverse_mass[i] <= 0.0) continue;
      const Vec3 velocity = motion ? Vec3(motion->A * row(x, i) + motion->c) : Vec3::Zero();
      v.row(i) = velocity.transpose();
    }
    return yields;
  }
  double mass = 0.0;
  Vec3 center = Vec3::Zero(), momentum = Vec3::Zero();
  for (int i : zone) {
    const double m = 1.0 / inverse_mass[i];
    mass += m;
    center += m * row(x, i);
    momentum += m * row(v, i);
    if (impulse) momentum += row(*impulse, i);
  }
  center /= mass;
  const Vec3 velocity = momentum / mass;
  Vec3 angular = Vec3::Zero();
  Mat3 inertia = Mat3::Zero();
  for (int i : zone) {
    const double m = 1.0 / inverse_mass[i];
    const Vec3 r = row(x, i) - center;
    angular += m * r.cross(row(v, i) - velocity);
    if (impulse) angular += r.cross(row(*impulse, i));
    inertia += m * (r.squaredNorm() * Mat3::Identity() - r * r.transpose());
  }
  // a zone on one line has no inertia about it: the pseudo-inverse leaves that spin out
  const Vec3 omega = inertia.completeOrthogonalDecomposition().solve(angular);
  const auto rigid = [&](int i) { return Vec3(velocity + omega.cross(row(x, i) - center)); };
  // a zone whose motion would take a vertex into the still surface it rests on holds still
  // instead: the surface holds it as a pin would
  bool into_support = false;
  if (support) {
    for (int i : zone) into_support = into_support || rigid(i).dot((*support)[i]) < 0.0;
  }
  for (int i : zone) v.row(i) = (into_support ? Vec3::Zero() : rigid(i)).transpose();
  return false;
}

}  // namespace

std::vector<std::vector<int>> SelfCollision::zone_members() const {
  std::vector<std::vector<int>> zones(vertex_count_);
  for (int i = 0; i < vertex_count_; ++i) {
    if (!in_zone_[i]) continue;
    int root = i;
    while (zone_parent_[root] != root) root = zone_parent_[root];
    zones[root].push_back(i);
  }
  return zones;
}

void SelfCollision::push_zones(const Points& x, Points& v, const Eigen::VectorXd& inverse_mass,
                               const SelfCollisionSettings& settings, const Points& impulse) const {
  if (over_budget_) return;
  // (the zones that gave way to an obstacle in impact_zones give way again: the same step)
  const double sink = collision_tolerance(settings) / passes_.dt;
  for (const std::vector<int>& zone : zone_members()) {
    if (!zone.empty()) {
      move_rigidly(zone, x, v, inverse_mass, &impulse, obstacle_of_, cloth_vertices_, settings, sink);
    }
  }
}

void SelfCollision::impact_zones(const Points& x, Points& v, const Eigen::VectorXd& inverse_mass, double dt,
                                 const SelfCollisionSettings& settings, SelfCollisionStatistics& stats) {
  std::vector<Contact> contacts;
  // 3. rigid impact zones until nothing collides
  std::vector<int>& parent = zone_parent_;
  parent.resize(vertex_count_);
  std::iota(parent.begin(), parent.end(), 0);
  in_zone_.assign(vertex_count_, 0);
  if (over_budget_) return;
  std::vector<char>& in_zone = in_zone_;
  // an obstacle carrying a zone into the surface under it more than the collision tolerance
  // over the step gives way (move_rigidly)
  const double sink = collision_tolerance(settings) / dt;
  const auto find = [&](int i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  };
  // a pair inside one zone moves with it by an invertible affine map, which passes nothing
  // through anything: only pairs reaching outside a zone are left to resolve
  const auto outside_zones = [&](std::vector<Contact>& list) {
    list.erase(std::remove_if(list.begin(), list.end(), [&](const Contact& c) {
                 const int zone = find(c.vertex[0]);
                 if (!in_zone[c.vertex[0]]) return false;
                 for (int k = 1; k < 4; ++k) {
                   if (!in_zone[c.vertex[k]] || find(c.vertex[k]) != zone) return false;
                 }
                 return true;
               }), list.end());
  };
  for (int round = 0; round < settings.zone_iterations; ++round) {
    collision_contacts(x, v, dt, settings, contacts, stats);
    outside_zones(contacts);
    if (contacts.empty()) return;
    ++stats.zone_rounds;
    stats.zone_round_peak = std::max<long long>(stats.zone_round_peak, round + 1);
    for (const Contact& c : contacts) {
      for (int k = 0; k < 4; ++k) {
        in_zone[c.vertex[k]] = 1;
        const int a = find(c.vertex[0]), b = find(c.vertex[k]);
        if (a != b) parent[std::max(a, b)] = std::min(a, b);
      }
    }
    // each zone's rigid motion: momentum and angular momentum about its centre of mass kept
    for (const std::vector<int>& zone : zone_members()) {
      if (zone.empty()) continue;
      stats.zone_vertices += static_cast<long long>(zone.size());
      stats.yields += move_rigidly(zone, x, v, inverse_mass, nullptr, obstacle_of_, cloth_vertices_, settings, sink);
    }
  }
  // the last resort: the cloth does not move, and a cloth free of crossings stays free of them
  // (unless a moving obstacle or attachment runs into it: those move as they must)
  collision_contacts(x, v, dt, settings, contacts, stats);
  if (over_budget_) return;  // (the caller holds the cloth still)
  outside_zones(contacts);
  if (contacts.empty()) return;
  ++stats.stills;
  for (int i = 0; i < cloth_vertices_; ++i) {
    if (inverse_mass[i] > 0.0) v.row(i).setZero();
  }
}

}  // namespace simbake
