// A keyed path for a kinematic body: poses of its mesh origin at times, linear in position
// and spherical-linear in orientation between keys, held at the first and last key outside.
#pragma once

#include "math/types.h"

#include <vector>

namespace simbake {

class KinematicTrack {
 public:
  KinematicTrack() = default;
  // times (s) strictly increasing; one origin (m) and one unit orientation per time
  KinematicTrack(std::vector<double> times, std::vector<Vec3> origins, std::vector<Quat> orientations);

  bool empty() const { return times_.empty(); }
  // mesh origin and orientation at time t (s)
  void pose_at(double t, Vec3& origin, Quat& orientation) const;

 private:
  std::vector<double> times_;
  std::vector<Vec3> origins_;
  std::vector<Quat> orientations_;
};

}  // namespace simbake
