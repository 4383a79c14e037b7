#include "contact/contact_bodies.h"

namespace simbake {

void ContactBodies::clear() {
  bodies_.clear();
  ground_.reset();
  v_.clear();
  l_.clear();
  asleep_.clear();
  impulses_.clear();
  woken_.clear();
  displacements_.clear();
}

void ContactBodies::add(const ContactBody& body, const Vec3& velocity, const Vec3& angular_momentum, bool asleep) {
  bodies_.push_back(body);
  v_.push_back(velocity);
  l_.push_back(angular_momentum);
  asleep_.push_back(asleep);
}

void ContactBodies::wake(int b) {
  const int island = bodies_[b].island;
  for (int j = 0; j < count(); ++j) {
    if (asleep_[j] && bodies_[j].island == island) asleep_[j] = 0;
  }
  woken_.push_back(b);
}

}  // namespace simbake
