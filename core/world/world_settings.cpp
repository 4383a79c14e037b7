#include "world/world_settings.h"

#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

namespace simbake {

namespace {

std::string shown(double x) {
  char text[32];
  std::snprintf(text, sizeof text, "%g", x);
  return text;
}

void positive(double x, const char* name) {
  if (!(x > 0.0 && std::isfinite(x))) throw std::invalid_argument(std::string(name) + " must be a finite number > 0, got " + shown(x));
}

void not_negative(double x, const char* name) {
  if (!(x >= 0.0 && std::isfinite(x))) throw std::invalid_argument(std::string(name) + " must be a finite number >= 0, got " + shown(x));
}

void at_least(int n, int least, const char* name) {
  if (n < least) throw std::invalid_argument(std::string(name) + " must be >= " + std::to_string(least) + ", got " + std::to_string(n));
}

}  // namespace

void check_settings(const WorldSettings& s) {
  if (!s.gravity.allFinite()) throw std::invalid_argument("gravity must be finite");
  at_least(s.collision_sweeps, 0, "collision_sweeps");
  at_least(s.contact_sweeps, 0, "contact_sweeps");
  at_least(s.shock_sweeps, 0, "shock_sweeps");
  not_negative(s.sleep_speed, "sleep_speed");
  not_negative(s.sleep_time, "sleep_time");
  not_negative(s.penetration_slop, "penetration_slop");
  not_negative(s.penetration_recovery, "penetration_recovery");
  not_negative(s.max_recovery_speed, "max_recovery_speed");
  positive(s.contact_tolerance, "contact_tolerance");
  positive(s.max_substep, "max_substep");
  positive(s.cloth_contact_substep, "cloth_contact_substep");
  positive(s.bounce_substep, "bounce_substep");
  positive(s.cloth_max_substep, "cloth_max_substep");
  positive(s.travel_fraction, "travel_fraction");
  positive(s.joint_turn, "joint_turn");
  at_least(s.max_substeps, 1, "max_substeps");
  if (s.threads < 0 || s.threads > kMaxThreads) {
    throw std::invalid_argument("threads must be in [0, " + std::to_string(kMaxThreads) + "] (0 = every CPU), got " +
                                std::to_string(s.threads));
  }
}

}  // namespace simbake
