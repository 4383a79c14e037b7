// Collision filtering (collision_filter.h).
#include "rigid/collision_filter.h"

#include <algorithm>
#include <stdexcept>

namespace simbake {

bool collision_filtered(const RigidModel& model, const RigidData& data, int a, int b) {
  // a joint between them that keeps them apart
  const std::vector<int>& joints = model.body_joints[a].size() <= model.body_joints[b].size() ? model.body_joints[a]
                                                                                              : model.body_joints[b];
  for (int j : joints) {
    const JointDef& def = model.joints[j];
    const bool between = (def.body0 == a && def.body1 == b) || (def.body0 == b && def.body1 == a);
    if (between && data.joints.enabled[j] && !def.collision_enabled) return true;
  }
  if (!model.filtered_pairs.empty() &&
      std::binary_search(model.filtered_pairs.begin(), model.filtered_pairs.end(), std::make_pair(std::min(a, b), std::max(a, b)))) {
    return true;
  }
  if (!model.group_filters.empty()) {
    for (int g = 0; g < static_cast<int>(model.group_filters.size()); ++g) {
      const std::uint64_t bit = std::uint64_t{1} << g;
      if (((model.groups[a] & bit) && (model.group_filters[g] & model.groups[b])) ||
          ((model.groups[b] & bit) && (model.group_filters[g] & model.groups[a]))) {
        return true;
      }
    }
  }
  return false;
}

void add_filtered_pair(RigidModel& model, int a, int b) {
  if (a < 0 || b < 0 || a >= model.body_count() || b >= model.body_count() || a == b) {
    throw std::invalid_argument("a filtered pair needs two different bodies");
  }
  const std::pair<int, int> pair(std::min(a, b), std::max(a, b));
  auto at = std::lower_bound(model.filtered_pairs.begin(), model.filtered_pairs.end(), pair);
  if (at == model.filtered_pairs.end() || *at != pair) model.filtered_pairs.insert(at, pair);
}

void set_collision_groups(RigidModel& model, const std::vector<std::vector<int>>& members,
                          const std::vector<std::vector<int>>& filters) {
  const int count = static_cast<int>(members.size());
  if (count > 64 || filters.size() != members.size()) {
    throw std::invalid_argument("collision groups: at most 64, each with its filters");
  }
  std::fill(model.groups.begin(), model.groups.end(), 0);
  model.group_filters.assign(count, 0);
  for (int g = 0; g < count; ++g) {
    for (int i : members[g]) {
      if (i < 0 || i >= model.body_count()) throw std::invalid_argument("collision group body index out of range");
      model.groups[i] |= std::uint64_t{1} << g;
    }
    for (int f : filters[g]) {
      if (f < 0 || f >= count) throw std::invalid_argument("collision group filter index out of range");
      model.group_filters[g] |= std::uint64_t{1} << f;
    }
  }
}

}  // namespace simbake
