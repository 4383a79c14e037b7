// Self-collision's repulsions (Bridson, Fedkiw and Anderson 2002, the first of the three
// parts at the top of self_collision.h), and the impulse of a contact they share with the
// continuous collisions.
#include "cloth/self_collision.h"

#include "cloth/self_collision_detail.h"

#include <cmath>

namespace simbake {

using namespace self_collision_detail;

namespace self_collision_detail {

bool apply_impulse(const SelfCollision::Contact& c, double target, double friction, Points& v,
                   const Eigen::VectorXd& inverse_mass, const std::vector<Vec3>* support) {
  Vec3 relative = Vec3::Zero();
  for (int k = 0; k < 4; ++k) relative += c.weight[k] * row(v, c.vertex[k]);
  const double vn = relative.dot(c.normal);
  const double change = target - vn;
  if (!(change > 0.0)) return false;
  // each vertex's share of the change moves it along weight x normal: into its support if
  // that points against the support's normal
  double mass[4], denom = 0.0;
  bool held = false;
  for (int k = 0; k < 4; ++k) {
    const int i = c.vertex[k];
    mass[k] = inverse_mass[i];
    if (support && c.weight[k] * c.normal.dot((*support)[i]) < 0.0 && mass[k] > 0.0) {
      mass[k] = 0.0;
      held = true;
    }
    denom += c.weight[k] * c.weight[k] * mass[k];
  }
  if (denom <= 0.0) return false;
  // vertex k's velocity changes by |w_k| m_k / denom times the wanted change: with the held
  // vertices out, a pair left with one free vertex of small weight (a triangle's far corner)
  // would fling it (by 1 / w_k, and faster every step after). Such a pair is left as one whose vertices are all held: to
  // the next passes and the impact zones
  if (held) {
    for (int k = 0; k < 4; ++k) {
      if (std::abs(c.weight[k]) * mass[k] > kMaxHeldAmplification * denom) return false;
    }
  }
  Vec3 delta = change * c.normal;  // the wanted change of the relative velocity
  const Vec3 slip = relative - vn * c.normal;
  const double slip_speed = slip.norm();
  if (slip_speed > 0.0) delta -= std::min(1.0, friction * change / slip_speed) * slip;
  for (int k = 0; k < 4; ++k) {
    const int i = c.vertex[k];
    v.row(i) += (c.weight[k] * mass[k] / denom) * delta.transpose();
  }
  return true;
}

}  // namespace self_collision_detail

namespace {

// the contact's relative velocity (first side minus second)
Vec3 relative_velocity(const SelfCollision::Contact& c, const Points& v) {
  Vec3 relative = Vec3::Zero();
  for (int k = 0; k < 4; ++k) relative += c.weight[k] * row(v, c.vertex[k]);
  return relative;
}

}  // namespace

void SelfCollision::repel(const Points& x, Points& v, const Eigen::VectorXd& inverse_mass, double dt,
                          const SelfCollisionSettings& settings, SelfCollisionStatistics& stats) {
  const double h = settings.thickness;
  if (!(h > 0.0) || over_budget_) return;
  const std::vector<Contact>& contacts = start(x, v, dt, settings, stats).proximity;
  if (over_budget_) return;
  // pairs in touch: the normal across both sides, turned against their approach now (before
  // any of this pass's impulses)
  std::vector<std::pair<size_t, Vec3>> touching;
  for (size_t k = 0; k < contacts.size(); ++k) {
    const Contact& c = contacts[k];
    if (c.distance <= 1e-9 * h) touching.emplace_back(k, relative_velocity(c, v).dot(c.normal) > 0.0 ? Vec3(-c.normal) : c.normal);
  }
  auto next = touching.begin();
  for (size_t k = 0; k < contacts.size(); ++k) {
    Contact c = contacts[k];
    if (next != touching.end() && next->first == k) c.normal = (next++)->second;
    stats.repulsions += apply_impulse(c, kRepulsionRate * (h - c.distance) / dt, settings.friction, v, inverse_mass,
                                      settings.support);
  }
}

}  // namespace simbake
