#include "rigid/integration.h"

#include "rigid/impulse_stage.h"

#include <tbb/parallel_for.h>

namespace simbake {

void update_velocities(const RigidModel& model, RigidData& data, const WorldSettings& settings, double dt) {
  for (int i = 0; i < model.body_count(); ++i) {
    if (!model.defs[i].kinematic && !data.asleep[i]) data.v[i] += dt * settings.gravity;
  }
}

void update_positions(const RigidModel& model, RigidData& data, RigidScratch& scratch, const WorldSettings& settings,
                      double dt) {
  scratch.dt = dt;
  scratch.candidates_with_forces = false;
  scratch.average_velocities = false;
  tbb::parallel_for(0, model.body_count(), [&](int i) {
    if (data.asleep[i]) return;
    update_candidate(model, data, scratch, settings, i);
    data.x[i] = scratch.candidate_x[i];
    data.q[i] = scratch.candidate_q[i];
  });
  scratch.log.stale.clear();
}

}  // namespace simbake
