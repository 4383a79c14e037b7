#include "rigid/kinematic_track.h"

#include <algorithm>
#include <stdexcept>

namespace simbake {

KinematicTrack::KinematicTrack(std::vector<double> times, std::vector<Vec3> origins, std::vector<Quat> orientations)
    : times_(std::move(times)), origins_(std::move(origins)), orientations_(std::move(orientations)) {
  if (times_.empty() || origins_.size() != times_.size() || orientations_.size() != times_.size()) {
    throw std::invalid_argument("a key track needs one position and one orientation per time");
  }
  for (std::size_t k = 0; k < times_.size(); ++k) {
    if (!std::isfinite(times_[k]) || !origins_[k].allFinite() || !orientations_[k].coeffs().allFinite() ||
        orientations_[k].norm() == 0.0) {
      throw std::invalid_argument("key times, positions and orientations must be finite");
    }
    if (k > 0 && !(times_[k] > times_[k - 1])) throw std::invalid_argument("key times must increase");
    orientations_[k].normalize();
    // take the short way round between consecutive keys
    if (k > 0 && orientations_[k].dot(orientations_[k - 1]) < 0.0) orientations_[k].coeffs() *= -1.0;
  }
}

void KinematicTrack::pose_at(double t, Vec3& origin, Quat& orientation) const {
  if (t <= times_.front()) {
    origin = origins_.front();
    orientation = orientations_.front();
    return;
  }
  if (t >= times_.back()) {
    origin = origins_.back();
    orientation = orientations_.back();
    return;
  }
  const std::size_t k = std::upper_bound(times_.begin(), times_.end(), t) - times_.begin();  // times_[k-1] < t < times_[k]
  const double s = (t - times_[k - 1]) / (times_[k] - times_[k - 1]);
  origin = (1.0 - s) * origins_[k - 1] + s * origins_[k];
  orientation = orientations_[k - 1].slerp(s, orientations_[k]);
}

}  // namespace simbake
