#include "contact/cloth_nearby.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <numeric>

namespace simbake {

namespace {
constexpr long long kCubesPerVertex = 4;  // the grid has at most this many cubes per vertex (and 64 more)
constexpr int kCubesAcross = 64;          // and cubes no smaller than 1/64 of the cloth's widest extent
// a point along an edge is computed from its ends' candidates in floating point: it may lie
// outside their box by a few ulps; boxes are grown by far more than that, relative to the
// coordinates' size
constexpr double kRoundOff = 1e-9;
}  // namespace

namespace {
// each vertex's items (the vertices of items[i] in `ends`) in increasing order, as (start, list)
template <class Ends>
void by_vertex(int vertex_count, const std::vector<Ends>& ends, std::vector<int>& start, std::vector<int>& items) {
  start.assign(vertex_count + 1, 0);
  for (const Ends& e : ends) {
    for (int k : e) ++start[k + 1];
  }
  std::partial_sum(start.begin(), start.end(), start.begin());
  items.resize(start.back());
  std::vector<int> fill(start.begin(), start.end() - 1);
  for (int i = 0; i < static_cast<int>(ends.size()); ++i) {
    for (int k : ends[i]) items[fill[k]++] = i;
  }
}
}  // namespace

ClothNearby::ClothNearby(int vertex_count, const std::vector<std::array<int, 2>>& edges, const Triangles& triangles)
    : vertex_count_(vertex_count), edges_(&edges) {
  by_vertex(vertex_count, edges, edge_start_, vertex_edges_);
  std::vector<std::array<int, 3>> corners(triangles.rows());
  for (int t = 0; t < triangles.rows(); ++t) corners[t] = {triangles(t, 0), triangles(t, 1), triangles(t, 2)};
  by_vertex(vertex_count, corners, triangle_start_, vertex_triangles_);
  moved_mark_.assign(vertex_count, 0);
  vertex_mark_.assign(vertex_count, 0);
  edge_mark_.assign(edges.size(), 0);
  triangle_mark_.assign(triangles.rows(), 0);
}

long long ClothNearby::cube(int axis, double coordinate) const {
  const double i = std::floor((coordinate - origin_[axis]) / size_);
  return static_cast<long long>(std::clamp(i, 0.0, static_cast<double>(counts_[axis] - 1)));
}

void ClothNearby::begin(const Points& candidates) {
  if (pass_ == std::numeric_limits<int>::max()) {
    std::fill(moved_mark_.begin(), moved_mark_.end(), 0);
    pass_ = 0;
  }
  ++pass_;
  moved_.clear();
  Box3 bounds;
  for (int k = 0; k < vertex_count_; ++k) bounds.extend(Vec3(candidates.row(k).transpose()));
  reach_ = 0.0;
  for (const auto& e : *edges_) {
    reach_ = std::max(reach_, (candidates.row(e[1]) - candidates.row(e[0])).cwiseAbs().maxCoeff());
  }
  const double magnitude = bounds.isEmpty() ? 0.0 : std::max(bounds.min().cwiseAbs().maxCoeff(), bounds.max().cwiseAbs().maxCoeff());
  reach_ += kRoundOff * (1.0 + magnitude);
  all_ = vertex_count_ == 0 || !bounds.min().allFinite() || !bounds.max().allFinite() || !std::isfinite(reach_);
  if (all_) return;
  // cubes as large as the longest edge, fewer than kCubesPerVertex a vertex
  const Vec3 extent = bounds.sizes();
  size_ = std::max({reach_, extent.maxCoeff() / kCubesAcross, kRoundOff * (1.0 + magnitude)});
  const auto volume = [&] {
    double v = 1.0;
    for (int a = 0; a < 3; ++a) v *= std::floor(extent[a] / size_) + 1.0;
    return v;
  };
  while (volume() > static_cast<double>(kCubesPerVertex * vertex_count_ + 64)) size_ *= 2.0;
  origin_ = bounds.min();
  for (int a = 0; a < 3; ++a) counts_[a] = static_cast<long long>(std::floor(extent[a] / size_)) + 1;
  // each cube's vertices, increasing (a counting sort)
  const long long cubes = counts_[0] * counts_[1] * counts_[2];
  std::vector<long long> home(vertex_count_);
  starts_.assign(cubes + 1, 0);
  for (int k = 0; k < vertex_count_; ++k) {
    home[k] = (cube(0, candidates(k, 0)) * counts_[1] + cube(1, candidates(k, 1))) * counts_[2] + cube(2, candidates(k, 2));
    ++starts_[home[k] + 1];
  }
  std::partial_sum(starts_.begin(), starts_.end(), starts_.begin());
  items_.resize(vertex_count_);
  std::vector<int> fill(starts_.begin(), starts_.end() - 1);
  for (int k = 0; k < vertex_count_; ++k) items_[fill[home[k]]++] = k;
}

void ClothNearby::gather(const Box3& box) {
  if (mark_ == std::numeric_limits<int>::max()) {
    std::fill(vertex_mark_.begin(), vertex_mark_.end(), 0);
    std::fill(edge_mark_.begin(), edge_mark_.end(), 0);
    std::fill(triangle_mark_.begin(), triangle_mark_.end(), 0);
    mark_ = 0;
  }
  ++mark_;
  found_.clear();
  const auto add = [&](int k) {
    if (vertex_mark_[k] == mark_) return;
    vertex_mark_[k] = mark_;
    found_.push_back(k);
  };
  if (all_) {
    for (int k = 0; k < vertex_count_; ++k) add(k);
    return;
  }
  if (box.isEmpty()) return;
  std::array<long long, 3> lo, hi;
  for (int a = 0; a < 3; ++a) {
    lo[a] = cube(a, box.min()[a]);
    hi[a] = cube(a, box.max()[a]);
  }
  for (long long i = lo[0]; i <= hi[0]; ++i) {
    for (long long j = lo[1]; j <= hi[1]; ++j) {
      const long long row = (i * counts_[1] + j) * counts_[2];
      for (int s = starts_[row + lo[2]]; s < starts_[row + hi[2] + 1]; ++s) add(items_[s]);
    }
  }
  for (int k : moved_) add(k);
}

namespace {
// (few: sorted; many beside the range they span: read off the marks in order)
void sorted_marked(std::vector<int>& found, const std::vector<int>& marks, int mark) {
  if (found.size() < 64) {
    std::sort(found.begin(), found.end());
    return;
  }
  const auto [lo, hi] = std::minmax_element(found.begin(), found.end());
  const int first = *lo, last = *hi;
  if (static_cast<double>(last - first) > 8.0 * found.size()) {
    std::sort(found.begin(), found.end());
    return;
  }
  found.clear();
  for (int i = first; i <= last; ++i) {
    if (marks[i] == mark) found.push_back(i);
  }
}
}  // namespace

const std::vector<int>& ClothNearby::vertices(const Box3& box) {
  gather(box);
  sorted_marked(found_, vertex_mark_, mark_);
  return found_;
}

void ClothNearby::items_of_found(const std::vector<int>& start, const std::vector<int>& items, std::vector<int>& marks) {
  ends_.swap(found_);  // (the vertices)
  found_.clear();
  for (int k : ends_) {
    for (int s = start[k]; s < start[k + 1]; ++s) {
      const int i = items[s];
      if (marks[i] == mark_) continue;
      marks[i] = mark_;
      found_.push_back(i);
    }
  }
  sorted_marked(found_, marks, mark_);
}

const std::vector<int>& ClothNearby::triangles(const Box3& box) {
  Box3 grown = box;
  grown.min().array() -= reach_;
  grown.max().array() += reach_;
  gather(grown);
  items_of_found(triangle_start_, vertex_triangles_, triangle_mark_);
  return found_;
}

void ClothNearby::begin_edges(const Box3& box) {
  Box3 grown = box;
  grown.min().array() -= reach_;
  grown.max().array() += reach_;
  gather(grown);
  items_of_found(edge_start_, vertex_edges_, edge_mark_);
  heap_.clear();
  next_ = 0;
  moved_seen_ = moved_.size();
  last_edge_ = -1;
}

int ClothNearby::next_edge() {
  // the edges of vertices moved since, not yet visited nor listed
  for (; moved_seen_ < moved_.size(); ++moved_seen_) {
    const int k = moved_[moved_seen_];
    for (int s = edge_start_[k]; s < edge_start_[k + 1]; ++s) {
      const int e = vertex_edges_[s];
      if (e <= last_edge_ || edge_mark_[e] == mark_) continue;
      edge_mark_[e] = mark_;
      heap_.push_back(e);
      std::push_heap(heap_.begin(), heap_.end(), std::greater<int>());
    }
  }
  const bool listed = next_ < found_.size();
  if (!listed && heap_.empty()) return -1;
  if (listed && (heap_.empty() || found_[next_] < heap_.front())) {
    last_edge_ = found_[next_++];
  } else {
    std::pop_heap(heap_.begin(), heap_.end(), std::greater<int>());
    last_edge_ = heap_.back();
    heap_.pop_back();
  }
  return last_edge_;
}

}  // namespace simbake
