#include "world/quality.h"

#include "geometry/triangle_intersection.h"
#include "rigid/box_contact.h"
#include "rigid/collision_filter.h"
#include "levelset/signed_distance.h"
#include "math/threads.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <utility>

namespace simbake {

namespace {

// Keeps the deepest of the depths offered to it (the first one on a tie, so the order of
// the loops decides and the result is the same on every run)
void offer(PenetrationFigure& deepest, double depth, int a, int b) {
  if (depth > deepest.depth) deepest = PenetrationFigure{depth, a, b};
}

// Two boxes: also edges crossing between the samples (the separating axes' depth)
void offer_box_overlap(const World& w, int a, int b, const std::vector<Pose>& poses, PenetrationFigure& deepest) {
  OrientedBox box_a, box_b;
  if (oriented_box(w.body_def(a).shape.get(), poses[a], box_a) && oriented_box(w.body_def(b).shape.get(), poses[b], box_b)) {
    offer(deepest, box_overlap_depth(box_a, box_b), a, b);
  }
}

// Body a's pose in body b's frame (b's pose the identity: in the world)
Pose relative(const Pose& a, const Pose& b) {
  return Pose{b.rotation.transpose() * a.rotation, b.rotation.transpose() * (a.translation - b.translation)};
}

// Samples [first, end) of body a inside body b's bounds, a_in_b a's pose in b's frame
void sample_range_inside(const World& w, int a, int b, const Pose& a_in_b, Eigen::Index first, Eigen::Index end,
                         PenetrationFigure& deepest) {
  const SignedDistance& shape_b = *w.body_def(b).shape;
  const Box3 bounds = shape_b.bounds();
  const Points& samples = w.body_def(a).samples;
  for (Eigen::Index s = first; s < end; ++s) {
    const Vec3 p = a_in_b.apply(samples.row(s).transpose());
    if (bounds.contains(p)) offer(deepest, -shape_b.phi(p), a, b);
  }
}

// Samples [first, end) of body a below the ground
void sample_range_below_ground(const World& w, int a, const std::vector<Pose>& poses, Eigen::Index first,
                               Eigen::Index end, PenetrationFigure& deepest) {
  const double height = w.ground()->height;
  const Points& samples = w.body_def(a).samples;
  for (Eigen::Index s = first; s < end; ++s) offer(deepest, height - poses[a].apply(samples.row(s).transpose()).y(), a, -1);
}

// The samples of sample block k of body a (rigid_body.h)
std::pair<Eigen::Index, Eigen::Index> block_samples(const RigidBodyDef& def, size_t k) {
  const Eigen::Index first = static_cast<Eigen::Index>(k) * SampleBlock::kSize;
  return {first, std::min<Eigen::Index>(first + SampleBlock::kSize, def.samples.rows())};
}

// Samples of body a inside body b, at the current poses
void samples_inside(const World& w, int a, int b, const std::vector<Pose>& poses, PenetrationFigure& deepest) {
  if (!w.body_def(b).shape) return;
  sample_range_inside(w, a, b, relative(poses[a], poses[b]), 0, w.body_def(a).samples.rows(), deepest);
  offer_box_overlap(w, a, b, poses, deepest);
}

// samples_inside a block of samples at a time: a block whose sphere misses b's bounds is
// passed over, its samples' points would all fail bounds.contains; the same depths of the
// same samples
void blocks_inside(const World& w, int a, int b, const std::vector<Pose>& poses, PenetrationFigure& deepest) {
  const RigidBodyDef& def_b = w.body_def(b);
  if (!def_b.shape) return;
  const Box3 bounds = def_b.shape->bounds();
  const RigidBodyDef& def_a = w.body_def(a);
  const Pose a_in_b = relative(poses[a], poses[b]);
  auto may_reach_bounds = [&](const SampleBlock& sphere) { return sphere.may_be_in(bounds, a_in_b.apply(sphere.centre)); };
  for_sample_blocks(def_a, may_reach_bounds, [&](size_t k) {
    const auto [first, end] = block_samples(def_a, k);
    sample_range_inside(w, a, b, a_in_b, first, end, deepest);
  });
  offer_box_overlap(w, a, b, poses, deepest);
}

// Every candidate of the body figure, in the order the figure is defined by: each dynamic
// body against the ground, then the pairs whose bounding spheres meet, in a sweep along x
// (the first of a pair a dynamic body, so that on a tie it is named as the one inside)
struct Candidate {
  int a = -1, b = -1;   // b = -1: the ground
  double bound = 0.0;   // no depth of this candidate exceeds it (m)
  std::uint64_t order;  // its place in the figure's order: the ground's by body, then the
                        // pairs by the sweep's ranks of their earlier and later body
};

// Where one body is now, and what bounds its samples' depths (its extent)
struct BodyReach {
  Pose pose;
  bool finite = true;
  OrientedBox box;  // (extent.is_box)
  BodyExtent extent;
};

// Depths and bounds are both computed in floating point from coordinates of a few metres:
// a bound this much above its exact value (m) stays above every depth it bounds
constexpr double kBoundSlack = 1e-6;

BodyReach body_reach(const World& w, int i, const BodyExtent& extent) {
  BodyReach r;
  r.pose = w.body_mesh_pose(i);
  r.finite = r.pose.rotation.allFinite() && r.pose.translation.allFinite();
  r.extent = extent;
  if (extent.is_box) r.box = {r.pose.translation, r.pose.rotation, extent.half};
  return r;
}

// The deepest any sample of body a can be under the ground: its box's lowest corner, or its
// mesh origin less the samples' reach
double ground_bound(double height, const BodyReach& a) {
  if (!a.finite) return INFINITY;
  if (a.extent.samples_in_box) {
    const Mat3& R = a.box.rotation;
    const double reach = a.box.half.dot(Vec3(std::abs(R(1, 0)), std::abs(R(1, 1)), std::abs(R(1, 2))));
    return height - (a.box.center.y() - reach) + kBoundSlack;
  }
  return height - (a.pose.translation.y() - a.extent.samples) + kBoundSlack;
}

// The least overlap of two boxes' projections on their 6 face axes (m; negative: apart by
// that much). Two boxes' SAT depth is at most this (it is the least over these axes and
// more), and so is how deep any point of one is inside the other (at most the shortest
// translation that separates them, itself at most the overlap along any axis). With
// C = Ra^T Rb, a's face axis i projects b to sum_k hb_k |C_ik|, b's axis j a to sum_k ha_k |C_kj|.
double face_overlap(const OrientedBox& a, const OrientedBox& b) {
  const Mat3 C = a.rotation.transpose() * b.rotation;
  const Vec3 d = b.center - a.center;
  const Vec3 da = a.rotation.transpose() * d, db = b.rotation.transpose() * d;
  double least = INFINITY;
  for (int i = 0; i < 3; ++i) {
    least = std::min(least, a.half[i] + b.half.dot(C.row(i).cwiseAbs().transpose()) - std::abs(da[i]));
    least = std::min(least, b.half[i] + a.half.dot(C.col(i).cwiseAbs()) - std::abs(db[i]));
  }
  return least;
}

// The deepest any sample of either body can be inside the other (and, two boxes, their SAT
// depth): for two boxes their face overlap; else a point within `samples` of one mesh origin
// and inside a solid that lies within `solid` of the other origin is no deeper than
// samples + solid - the origins' distance. Negative: apart, every depth <= 0 (a figure counts
// only depths > 0; two boxes' SAT depth is 0 when they are apart).
double pair_bound(const BodyReach& a, const BodyReach& b) {
  if (!a.finite || !b.finite) return INFINITY;
  const BodyExtent &ea = a.extent, &eb = b.extent;
  const double overlap = ea.is_box && eb.is_box ? face_overlap(a.box, b.box) : -INFINITY;
  if (ea.samples_in_box && eb.samples_in_box) return overlap + kBoundSlack;
  const double apart = (a.pose.translation - b.pose.translation).norm();
  return std::max(overlap, std::max(ea.samples + eb.solid, eb.samples + ea.solid) - apart) + kBoundSlack;
}

// Whether the bounding spheres of bodies i and j meet (i the earlier in the sweep's order)
bool spheres_meet(const World& w, int i, int j) {
  return !((w.rigid_data().x[j] - w.rigid_data().x[i]).norm() > w.body_def(i).bounding_radius + w.body_def(j).bounding_radius);
}

// The pairs whose bounding spheres meet, each as (i, j) with i before j in `order` (the
// bodies sorted by the low end of their spheres along x), in the order a sweep along x
// passes them: every body against the ones after it whose spheres start before its own ends.
// A sweep passes the bodies in the same slab of x: O(n^2) for a pile as wide as it is high.
std::vector<std::array<int, 2>> pairs_by_sweep(const World& w, const std::vector<int>& order) {
  const int n = w.body_count();
  const auto low = [&w](int i) { return w.rigid_data().x[i].x() - w.body_def(i).bounding_radius; };
  std::vector<std::array<int, 2>> out;
  for (int p = 0; p < n; ++p) {
    const int i = order[p];
    const double high = w.rigid_data().x[i].x() + w.body_def(i).bounding_radius;
    for (int q = p + 1; q < n && low(order[q]) <= high; ++q) {
      if (spheres_meet(w, i, order[q])) out.push_back({i, order[q]});
    }
  }
  return out;
}

// The same pairs (each as the sweep has it; in no particular order) from a grid of cubes as wide as the largest sphere of most
// bodies (the widest tenth, if much wider, is checked against every body), each body against
// the bodies in its cube and the 26 around it: a pair of spheres that meet is at most one
// cube apart on each axis (a sphere that meets another only within round-off of touching may
// be counted here and not by the sweep: it holds no depth). false (and nothing) when the
// bodies do not suit a grid (positions not finite, too many wide bodies).
bool pairs_by_grid(const World& w, const std::vector<int>& rank, std::vector<std::array<int, 2>>& out) {
  const int n = w.body_count();
  if (n < 2) return true;  // (no pairs)
  std::vector<double> radii(n);
  for (int i = 0; i < n; ++i) {
    radii[i] = w.body_def(i).bounding_radius;
    if (!w.rigid_data().x[i].allFinite() || !std::isfinite(radii[i])) return false;
  }
  std::vector<double> sorted = radii;
  const auto tenth = sorted.begin() + (9 * static_cast<std::ptrdiff_t>(n)) / 10;
  std::nth_element(sorted.begin(), tenth, sorted.end());
  const double cube = 2.0 * *tenth * (1.0 + 1e-6);  // (a margin over the round-off of x / cube)
  if (!(cube > 0.0)) return false;
  // each cube as one key, 21 bits an axis: the cubes of a row along z are consecutive keys
  constexpr std::int64_t kSpan = std::int64_t{1} << 20;
  const auto key = [](std::int64_t cx, std::int64_t cy, std::int64_t cz) {
    return static_cast<std::uint64_t>(((cx + kSpan) << 42) | ((cy + kSpan) << 21) | (cz + kSpan));
  };
  std::vector<int> wide;
  std::vector<std::array<std::int64_t, 3>> cells(n);
  std::vector<std::pair<std::uint64_t, int>> entries;  // (cube, body)
  for (int i = 0; i < n; ++i) {
    if (2.0 * radii[i] > cube) {
      wide.push_back(i);
      continue;
    }
    const Vec3 c = w.rigid_data().x[i] / cube;
    if (c.cwiseAbs().maxCoeff() > static_cast<double>(kSpan - 2)) return false;
    cells[i] = {static_cast<std::int64_t>(std::floor(c.x())), static_cast<std::int64_t>(std::floor(c.y())),
                static_cast<std::int64_t>(std::floor(c.z()))};
    entries.push_back({key(cells[i][0], cells[i][1], cells[i][2]), i});
  }
  if (wide.size() > 64) return false;
  const auto add = [&](int i, int j) {  // i and j in either order
    if (rank[j] < rank[i]) std::swap(i, j);
    if (spheres_meet(w, i, j)) out.push_back({i, j});
  };
  // the bodies of each cube, as buckets of a dense block of cubes (with a layer of empty ones
  // around) when it is small beside the bodies, else as sorted (cube, body) entries
  std::array<std::int64_t, 3> low{}, size{};
  low.fill(std::numeric_limits<std::int64_t>::max());
  size.fill(0);
  for (const auto& [k, i] : entries) {
    for (int a = 0; a < 3; ++a) low[a] = std::min(low[a], cells[i][a] - 1);
  }
  for (const auto& [k, i] : entries) {
    for (int a = 0; a < 3; ++a) size[a] = std::max(size[a], cells[i][a] + 2 - low[a]);
  }
  const double volume = static_cast<double>(size[0]) * static_cast<double>(size[1]) * static_cast<double>(size[2]);
  if (!entries.empty() && volume <= 8.0 * n + 64.0) {
    const auto block = [&](std::int64_t cx, std::int64_t cy, std::int64_t cz) {
      return ((cx - low[0]) * size[1] + (cy - low[1])) * size[2] + (cz - low[2]);
    };
    std::vector<int> starts(static_cast<size_t>(volume) + 1, 0), bodies(entries.size());
    for (const auto& [k, i] : entries) ++starts[block(cells[i][0], cells[i][1], cells[i][2]) + 1];
    std::partial_sum(starts.begin(), starts.end(), starts.begin());
    std::vector<int> fill(starts.begin(), starts.end() - 1);
    for (const auto& [k, i] : entries) bodies[fill[block(cells[i][0], cells[i][1], cells[i][2])]++] = i;
    for (const auto& [own, i] : entries) {
      const auto& c = cells[i];
      for (std::int64_t dx = -1; dx <= 1; ++dx) {
        for (std::int64_t dy = -1; dy <= 1; ++dy) {
          const std::int64_t row = block(c[0] + dx, c[1] + dy, c[2]);
          for (int s = starts[row - 1]; s < starts[row + 2]; ++s) {
            if (rank[bodies[s]] > rank[i]) add(i, bodies[s]);
          }
        }
      }
    }
  } else {
    std::sort(entries.begin(), entries.end());
    for (const auto& [own, i] : entries) {
      const auto& c = cells[i];
      for (std::int64_t dx = -1; dx <= 1; ++dx) {
        for (std::int64_t dy = -1; dy <= 1; ++dy) {
          const std::uint64_t last = key(c[0] + dx, c[1] + dy, c[2] + 1);
          auto it = std::lower_bound(entries.begin(), entries.end(), std::make_pair(key(c[0] + dx, c[1] + dy, c[2] - 1), -1));
          for (; it != entries.end() && it->first <= last; ++it) {
            if (rank[it->second] > rank[i]) add(i, it->second);
          }
        }
      }
    }
  }
  for (size_t k = 0; k < wide.size(); ++k) {
    for (int j = 0; j < n; ++j) {
      const bool wide_j = 2.0 * radii[j] > cube;
      if (j != wide[k] && (!wide_j || rank[j] > rank[wide[k]])) add(wide[k], j);
    }
  }
  return true;
}

// The candidates of the body figure with their bounds and places in its order (pairs from a
// grid, or with `sweep` as the figure defines them, in its order)
std::vector<Candidate> candidates(const World& w, const std::vector<BodyReach>& reach, bool sweep = false) {
  const int n = w.body_count();
  std::vector<Candidate> out;
  if (w.ground()) {
    for (int a = 0; a < n; ++a) {
      if (!w.body_def(a).kinematic) out.push_back({a, -1, ground_bound(w.ground()->height, reach[a]), std::uint64_t(a)});
    }
  }
  std::vector<int> order(n), rank(n);
  std::vector<double> low(n);  // the low end of each body's sphere along x
  for (int i = 0; i < n; ++i) low[i] = w.rigid_data().x[i].x() - w.body_def(i).bounding_radius;
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&low](int i, int j) { return low[i] < low[j]; });
  for (int p = 0; p < n; ++p) rank[order[p]] = p;
  std::vector<std::array<int, 2>> pairs;
  if (sweep || !pairs_by_grid(w, rank, pairs)) pairs = pairs_by_sweep(w, order);
  for (const auto& [i, j] : pairs) {
    if (w.body_def(i).kinematic && w.body_def(j).kinematic) continue;
    // (a pair kept from colliding, jointed or filtered, may overlap)
    if (w.rigid_model().filters_collisions() && collision_filtered(w.rigid_model(), w.rigid_data(), i, j)) continue;
    const bool i_first = !w.body_def(i).kinematic;
    const std::uint64_t order = (std::uint64_t{1} << 63) | (static_cast<std::uint64_t>(rank[i]) << 31) |
                                static_cast<std::uint64_t>(rank[j]);
    out.push_back({i_first ? i : j, i_first ? j : i, pair_bound(reach[i], reach[j]), order});
  }
  return out;
}

std::uint64_t memo_key(const Candidate& c) {
  const auto lower = static_cast<std::uint32_t>(c.b < 0 ? c.a : std::min(c.a, c.b));
  const auto higher = c.b < 0 ? ~std::uint32_t{0} : static_cast<std::uint32_t>(std::max(c.a, c.b));
  return (static_cast<std::uint64_t>(lower) << 32) | higher;
}

bool same_pose(const Pose& p, const Pose& q) {
  return std::memcmp(p.rotation.data(), q.rotation.data(), 9 * sizeof(double)) == 0 &&
         std::memcmp(p.translation.data(), q.translation.data(), 3 * sizeof(double)) == 0;
}

// The shapes and samples of the candidate's bodies those it was measured with
void shapes_of(const World& w, int a, int b, const void* out[4]) {
  out[0] = w.body_def(a).shape.get();
  out[1] = w.body_def(a).samples.data();
  out[2] = b < 0 ? nullptr : w.body_def(b).shape.get();
  out[3] = b < 0 ? nullptr : w.body_def(b).samples.data();
}

bool same_shapes(const World& w, const DepthMemo::Known& known) {
  const void* now[4];
  shapes_of(w, known.a, known.b, now);
  return std::memcmp(now, known.shapes, sizeof now) == 0;
}

// How far a point within `reach` of the origin moves between two poses (m):
// |(R1 - R0) s + t1 - t0| <= ||R1 - R0|| |s| + |t1 - t0|, and R1 - R0 = R0 (R0^T R1 - I) with
// R0^T R1 a turn by some angle a: its norm 2 sin(a / 2) = sqrt(3 - trace(R0^T R1)) (a little
// more, for the round-off of the trace)
double moved(const Pose& from, const Pose& to, double reach) {
  const double trace = (from.rotation.transpose() * to.rotation).trace();
  const double turn = std::sqrt(std::max(0.0, 3.0 - trace) + 1e-14);
  return turn * reach + (to.translation - from.translation).norm();
}

// The depth a candidate measured before can have now at most (INFINITY: no bound): each
// sample of one body can have moved only so far through the other's field, whose phi changes
// by at most its Lipschitz constant per metre (a sample outside the other's bounds then had
// phi >= 0). Two boxes' separating-axis depth is not bounded so: none for them.
double motion_bound(const World& w, const Candidate& c, const DepthMemo::Known& known,
                    const std::vector<BodyReach>& reach, const std::vector<Pose>& poses) {
  const RigidBodyDef& def_a = w.body_def(c.a);
  const bool same = known.a == c.a && known.b == c.b;  // (else the poses are the other way round)
  const Pose& then_a = same ? known.pose_a : known.pose_b;
  const Pose& then_b = same ? known.pose_b : known.pose_a;
  if (!same_shapes(w, known)) return INFINITY;
  if (!reach[c.a].finite || (c.b >= 0 && !reach[c.b].finite)) return INFINITY;
  double motion = 0.0;
  if (c.b < 0) {
    motion = moved(then_a, poses[c.a], reach[c.a].extent.samples);
  } else {
    if (reach[c.a].extent.is_box && reach[c.b].extent.is_box) return INFINITY;
    const RigidBodyDef& def_b = w.body_def(c.b);
    if (def_b.shape) {
      motion = def_b.shape->lipschitz() * moved(relative(then_a, then_b), relative(poses[c.a], poses[c.b]),
                                                reach[c.a].extent.samples);
    }
    if (def_a.shape) {
      motion = std::max(motion, def_a.shape->lipschitz() * moved(relative(then_b, then_a), relative(poses[c.b], poses[c.a]),
                                                                 reach[c.b].extent.samples));
    }
  }
  return known.depth.depth + motion * (1.0 + 1e-9) + kBoundSlack;
}

// candidate_depth a block of samples at a time: a block that cannot hold a depth above the
// deepest so far is passed over (its samples would not replace it: the same figure)
PenetrationFigure candidate_depth_by_blocks(const World& w, const Candidate& c, const std::vector<Pose>& poses) {
  PenetrationFigure deepest;
  if (c.b < 0) {
    const double height = w.ground()->height;
    const RigidBodyDef& def = w.body_def(c.a);
    auto may_be_deeper = [&](const SampleBlock& sphere) {
      const Vec3 centre = poses[c.a].apply(sphere.centre);
      return height - (centre.y() - SampleBlock::slackened(centre, sphere.margin)) > deepest.depth;
    };
    for_sample_blocks(def, may_be_deeper, [&](size_t k) {
      const auto [first, end] = block_samples(def, k);
      sample_range_below_ground(w, c.a, poses, first, end, deepest);
    });
    return deepest;
  }
  blocks_inside(w, c.a, c.b, poses, deepest);
  blocks_inside(w, c.b, c.a, poses, deepest);
  return deepest;
}

// The deepest of one candidate's depths, first on a tie, as the figure's loops offer them
PenetrationFigure candidate_depth(const World& w, const Candidate& c, const std::vector<Pose>& poses) {
  PenetrationFigure deepest;
  if (c.b < 0) {
    sample_range_below_ground(w, c.a, poses, 0, w.body_def(c.a).samples.rows(), deepest);
    return deepest;
  }
  samples_inside(w, c.a, c.b, poses, deepest);
  samples_inside(w, c.b, c.a, poses, deepest);
  return deepest;
}

}  // namespace

BodyExtent body_extent(const RigidBodyDef& def) {
  BodyExtent e;
  e.shape = def.shape.get();
  e.samples_at = def.samples.data();
  e.sample_count = def.samples.rows();
  for (Eigen::Index s = 0; s < def.samples.rows(); ++s) e.samples = std::max(e.samples, def.samples.row(s).norm());
  OrientedBox box;
  if (const auto* sphere = dynamic_cast<const SphereDistance*>(def.shape.get())) {
    e.solid = -sphere->phi(Vec3::Zero());
  } else if (oriented_box(def.shape.get(), Pose{}, box)) {
    e.half = box.half;
    e.solid = box.half.norm();
    e.is_box = true;
    e.samples_in_box = true;
    for (Eigen::Index s = 0; s < def.samples.rows(); ++s) {
      e.samples_in_box = e.samples_in_box && (def.samples.row(s).transpose().cwiseAbs() - box.half).maxCoeff() <= 0.0;
    }
  } else if (!def.shape) {
    e.solid = 0.0;  // (nothing is inside a body without a shape)
  }
  return e;
}

PenetrationFigure body_penetration(const World& w) {
  std::vector<BodyExtent> extents(w.body_count());
  for (int i = 0; i < w.body_count(); ++i) extents[i] = body_extent(w.body_def(i));
  return body_penetration(w, extents);
}

PenetrationFigure body_penetration_every_sample(const World& w) {
  const int n = w.body_count();
  std::vector<BodyReach> reach(n);
  std::vector<Pose> poses(n);
  for (int i = 0; i < n; ++i) poses[i] = w.body_mesh_pose(i);
  PenetrationFigure deepest;
  for (const Candidate& c : candidates(w, reach, true)) {
    const PenetrationFigure d = candidate_depth(w, c, poses);
    offer(deepest, d.depth, d.a, d.b);
  }
  return deepest;
}

// The candidates deepest bound first: once a bound is below the deepest depth found, no
// later candidate can be deeper (nor tie: a tie goes to the candidate first in the figure's
// order, so a candidate whose bound equals the deepest is still measured, and the first of
// the deepest is kept whatever the order they were measured in)
PenetrationFigure body_penetration(const World& w, const std::vector<BodyExtent>& extents, DepthMemo* memo) {
  const int n = w.body_count();
  std::vector<BodyReach> reach(n);
  std::vector<Pose> poses(n);
  for (int i = 0; i < n; ++i) {
    reach[i] = body_reach(w, i, extents[i]);
    poses[i] = reach[i].pose;
  }
  const std::vector<Candidate> all = candidates(w, reach);
  // the candidates that may hold a depth (> 0), as a heap by bound: every candidate whose
  // bound is not below the final deepest depth is measured, in whatever order they come
  std::vector<std::pair<double, int>> heap;
  std::vector<const DepthMemo::Known*> known(all.size(), nullptr);
  for (int k = 0; k < static_cast<int>(all.size()); ++k) {
    double bound = std::isnan(all[k].bound) ? INFINITY : all[k].bound;
    if (memo) {
      const auto found = memo->last.find(memo_key(all[k]));
      if (found != memo->last.end()) {
        known[k] = &found->second;
        bound = std::min(bound, motion_bound(w, all[k], found->second, reach, poses));
      }
    }
    if (bound > 0.0) heap.push_back({bound, k});
  }
  std::make_heap(heap.begin(), heap.end());
  // in batches (each twice the last) measured in parallel, then offered in turn: the deepest
  // and the first of the deepest do not depend on the order, and a candidate measured past
  // the point a lone loop would stop holds no depth above the final one
  PenetrationFigure deepest;
  std::uint64_t first = 0;  // the place of the candidate that gave `deepest`
  std::vector<int> batch;
  std::vector<PenetrationFigure> depths;
  for (std::size_t size = 16; !heap.empty() && !(heap.front().first < deepest.depth); size *= 2) {
    batch.clear();
    while (!heap.empty() && batch.size() < size && !(heap.front().first < deepest.depth)) {
      batch.push_back(heap.front().second);
      std::pop_heap(heap.begin(), heap.end());
      heap.pop_back();
    }
    depths.assign(batch.size(), PenetrationFigure{});
    tbb::parallel_for(std::size_t{0}, batch.size(), [&](std::size_t t) {
      const Candidate& c = all[batch[t]];
      const DepthMemo::Known* k = known[batch[t]];
      // (the same bodies where they were, in the same order: the same figure)
      if (k && k->a == c.a && k->b == c.b && same_pose(k->pose_a, poses[c.a]) &&
          (c.b < 0 || same_pose(k->pose_b, poses[c.b])) && same_shapes(w, *k)) {
        depths[t] = k->depth;
        return;
      }
      depths[t] = candidate_depth_by_blocks(w, c, poses);
    });
    for (std::size_t t = 0; t < batch.size(); ++t) {
      const PenetrationFigure& d = depths[t];
      if (memo) {
        const Candidate& c = all[batch[t]];
        DepthMemo::Known& k = memo->next[memo_key(c)];
        k.depth = d;
        k.a = c.a;
        k.b = c.b;
        k.pose_a = poses[c.a];
        k.pose_b = c.b < 0 ? Pose{} : poses[c.b];
        shapes_of(w, c.a, c.b, k.shapes);
      }
      const std::uint64_t order = all[batch[t]].order;
      if (d.depth > deepest.depth || (d.a >= 0 && d.depth == deepest.depth && order < first)) {
        deepest = d;
        first = order;
      }
    }
  }
  if (memo) {
    // (a candidate passed over keeps what was measured of it, from the poses it was measured at)
    for (size_t k = 0; k < all.size(); ++k) {
      if (known[k]) memo->next.emplace(memo_key(all[k]), *known[k]);
    }
    std::swap(memo->last, memo->next);
    memo->next.clear();
  }
  return deepest;
}

ClothQuality cloth_quality(const World& w, int c) {
  const Cloth& cloth = w.cloth(c);
  const Points& x = cloth.positions();
  ClothQuality q;
  q.max_strain = cloth.max_strain();
  try {
    q.self_intersections =
        static_cast<long long>(intersecting_triangle_pairs(x, cloth.triangles(), kPairTestBudget).size());
  } catch (const std::length_error&) {
    q.self_intersections = -1;  // (not counted: the QA says so)
  }

  // bodies whose bounding spheres reach the cloth's box, with their poses
  Box3 box;
  for (Eigen::Index k = 0; k < x.rows(); ++k) box.extend(x.row(k).transpose());
  std::vector<int> near;
  std::vector<Pose> poses;
  for (int b = 0; b < w.body_count(); ++b) {
    const Vec3& center = w.rigid_data().x[b];
    if (!w.body_def(b).shape || box.isEmpty()) continue;
    if ((center.cwiseMax(box.min()).cwiseMin(box.max()) - center).norm() > w.body_def(b).bounding_radius) continue;
    near.push_back(b);
    poses.push_back(w.body_mesh_pose(b));
  }
  // how deep a point is inside the ground or a body, past its surface
  const auto probe = [&](const Vec3& p, PenetrationFigure& deepest) {
    if (w.ground()) offer(deepest, w.ground()->height - p.y(), c, -1);
    for (size_t k = 0; k < near.size(); ++k) {
      const int b = near[k];
      if ((p - w.rigid_data().x[b]).norm() > w.body_def(b).bounding_radius) continue;
      offer(deepest, -w.body_def(b).shape->phi(poses[k].apply_inverse(p)), c, b);
    }
  };
  // the points in parallel: each range's first deepest, the earlier range's on a tie, is the
  // first deepest of all in any split, as in order
  const auto deepest = [](std::size_t count, auto&& offer_of) {
    return tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, count, 64), PenetrationFigure{},
        [&](const tbb::blocked_range<std::size_t>& range, PenetrationFigure d) {
          for (std::size_t k = range.begin(); k < range.end(); ++k) offer_of(k, d);
          return d;
        },
        [](const PenetrationFigure& l, const PenetrationFigure& r) { return r.depth > l.depth ? r : l; });
  };
  q.vertex_penetration =
      deepest(static_cast<std::size_t>(x.rows()), [&](std::size_t k, PenetrationFigure& d) { probe(x.row(k).transpose(), d); });
  const auto& edges = w.cloth_edges(c);
  q.edge_penetration = deepest(edges.size(), [&](std::size_t e, PenetrationFigure& d) {
    const Vec3 a = x.row(edges[e][0]).transpose(), b = x.row(edges[e][1]).transpose();
    // eighths: finer than the cloth's own edge contacts (quarters), so the figure judges them
    for (int k = 1; k < 8; ++k) probe(a + (k / 8.0) * (b - a), d);
  });
  return q;
}

bool QualityMeter::same_bodies_and_ground(const World& w) const {
  const double ground = w.ground() ? w.ground()->height : NAN;
  return measured_ && static_cast<int>(poses_.size()) == 7 * w.body_count() && std::memcmp(&ground, &ground_, sizeof ground) == 0;
}

bool QualityMeter::unchanged(const World& w) const {
  if (!same_bodies_and_ground(w)) return false;
  const int n = w.body_count();
  for (int i = 0; i < n; ++i) {
    const RigidBodyDef& def = w.body_def(i);
    if (shapes_[2 * i] != def.shape.get() || shapes_[2 * i + 1] != def.samples.data()) return false;
    const Vec3& x = w.rigid_data().x[i];
    const Quat& q = w.rigid_data().q[i];
    const double now[7] = {x.x(), x.y(), x.z(), q.w(), q.x(), q.y(), q.z()};
    if (std::memcmp(now, &poses_[7 * i], sizeof now) != 0) return false;
  }
  return w.rigid_data().joints.enabled == joints_enabled_;
}

void QualityMeter::remember(const World& w) {
  const int n = w.body_count();
  poses_.resize(7 * n);
  shapes_.resize(2 * n);
  for (int i = 0; i < n; ++i) {
    const Vec3& x = w.rigid_data().x[i];
    const Quat& q = w.rigid_data().q[i];
    const double now[7] = {x.x(), x.y(), x.z(), q.w(), q.x(), q.y(), q.z()};
    std::memcpy(&poses_[7 * i], now, sizeof now);
    shapes_[2 * i] = w.body_def(i).shape.get();
    shapes_[2 * i + 1] = w.body_def(i).samples.data();
  }
  joints_enabled_ = w.rigid_data().joints.enabled;
  ground_ = w.ground() ? w.ground()->height : NAN;
  measured_ = true;
}

FrameQuality QualityMeter::measure(const World& w) {
  return on_threads(w.settings().threads, [&] { return measure_on_arena(w); });
}

FrameQuality QualityMeter::measure_on_arena(const World& w) {
  if (!unchanged(w)) {
    // (another ground, or other bodies: no depth measured before holds)
    if (!same_bodies_and_ground(w)) memo_.last.clear();
    extents_.resize(w.body_count());
    for (int i = 0; i < w.body_count(); ++i) {
      const RigidBodyDef& def = w.body_def(i);
      const BodyExtent& e = extents_[i];
      if (e.shape != def.shape.get() || e.samples_at != def.samples.data() || e.sample_count != def.samples.rows()) {
        extents_[i] = body_extent(def);
      }
    }
    body_ = body_penetration(w, extents_, &memo_);
    remember(w);
  }
  FrameQuality quality;
  quality.body_penetration = body_;
  for (int c = 0; c < w.cloth_count(); ++c) quality.cloths.push_back(cloth_quality(w, c));
  return quality;
}

FrameQuality measure_quality(const World& w) {
  return on_threads(w.settings().threads, [&] {
    FrameQuality quality;
    quality.body_penetration = body_penetration(w);
    for (int c = 0; c < w.cloth_count(); ++c) quality.cloths.push_back(cloth_quality(w, c));
    return quality;
  });
}

}  // namespace simbake
