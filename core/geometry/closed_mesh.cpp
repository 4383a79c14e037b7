#include "geometry/closed_mesh.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace simbake {

namespace {

// Twice the signed area of (a, b, q): which side of the line a -> b q is on
double side(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& q) {
  return (b.x() - a.x()) * (q.y() - a.y()) - (b.y() - a.y()) * (q.x() - a.x());
}

double segment_distance(const Vec3& p, const Vec3& u, const Vec3& v) {
  const Vec3 e = v - u;
  const double ee = e.squaredNorm();
  const double t = ee > 0.0 ? std::clamp((p - u).dot(e) / ee, 0.0, 1.0) : 0.0;
  return (p - (u + t * e)).norm();
}

// Distance from p to triangle abc: to the plane's closest point when it falls inside the
// triangle, else to the nearest edge (a triangle of no area is its edges)
double triangle_distance(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 n = (b - a).cross(c - a);
  const double nn = n.squaredNorm();
  if (nn > 0.0) {
    const double height = (p - a).dot(n);
    const Vec3 proj = p - (height / nn) * n;
    if ((b - a).cross(proj - a).dot(n) >= 0.0 && (c - b).cross(proj - b).dot(n) >= 0.0 &&
        (a - c).cross(proj - c).dot(n) >= 0.0) {
      return std::abs(height) / std::sqrt(nn);
    }
  }
  return std::min({segment_distance(p, a, b), segment_distance(p, b, c), segment_distance(p, c, a)});
}

double median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  const auto mid = values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2);
  std::nth_element(values.begin(), mid, values.end());
  return *mid;
}

// Cells of `cell` covering [lo, hi] from origin, coarsened (the cell doubled) until there are
// at most `most` of them
template <int D>
Eigen::Matrix<int, D, 1> cover(const Eigen::Matrix<double, D, 1>& extent, double& cell, long long most) {
  for (;;) {
    Eigen::Matrix<int, D, 1> size;
    long long total = 1;
    for (int k = 0; k < D; ++k) {
      size[k] = static_cast<int>(std::floor(extent[k] / cell)) + 1;
      total *= size[k];
    }
    if (total <= most) return size;
    cell *= 2.0;
  }
}

// CSR bins: each item's range of cells (lo..hi inclusive, row-major in `size`) -> start
// offsets per cell and the items of each cell in item order
template <int D>
void bin(const std::vector<Eigen::Matrix<int, D, 1>>& lo, const std::vector<Eigen::Matrix<int, D, 1>>& hi,
         const Eigen::Matrix<int, D, 1>& size, std::vector<int>& start, std::vector<int>& items) {
  long long cells = 1;
  for (int k = 0; k < D; ++k) cells *= size[k];
  start.assign(static_cast<size_t>(cells) + 1, 0);
  auto each_cell = [&](size_t t, auto&& f) {
    Eigen::Matrix<int, D, 1> c = lo[t];
    for (;;) {
      long long key = 0;
      for (int k = D - 1; k >= 0; --k) key = key * size[k] + c[k];
      f(static_cast<size_t>(key));
      int k = 0;
      while (k < D && ++c[k] > hi[t][k]) c[k] = lo[t][k], ++k;
      if (k == D) return;
    }
  };
  for (size_t t = 0; t < lo.size(); ++t) each_cell(t, [&](size_t key) { ++start[key + 1]; });
  for (size_t k = 1; k < start.size(); ++k) start[k] += start[k - 1];
  items.resize(static_cast<size_t>(start.back()));
  std::vector<int> fill(start.begin(), start.end() - 1);
  for (size_t t = 0; t < lo.size(); ++t) each_cell(t, [&](size_t key) { items[fill[key]++] = static_cast<int>(t); });
}

}  // namespace

ClosedMesh::RayFrame::RayFrame(int axis) {
  // a direction no mesh's edges line up with, leaning most along `axis`
  const Vec3 lean(1.0, 0.1414213562, 0.2718281828);
  for (int k = 0; k < 3; ++k) ray[(axis + k) % 3] = lean[k];
  ray.normalize();
  u = ray.cross(Vec3::UnitX()).normalized();
  w = ray.cross(u);
}

ClosedMesh::ClosedMesh(const Points& vertices, const Triangles& triangles) {
  const size_t m = static_cast<size_t>(triangles.rows());
  const Eigen::Index n = vertices.rows();
  for (auto* corners : {&a_, &b_, &c_}) corners->reserve(m);
  for (Eigen::Index t = 0; t < triangles.rows(); ++t) {
    for (int k = 0; k < 3; ++k) {
      if (triangles(t, k) < 0 || triangles(t, k) >= n) {
        throw std::out_of_range("triangle " + std::to_string(t) + " names vertex " +
                                std::to_string(triangles(t, k)) + " of " + std::to_string(n));
      }
    }
    a_.push_back(vertices.row(triangles(t, 0)).transpose());
    b_.push_back(vertices.row(triangles(t, 1)).transpose());
    c_.push_back(vertices.row(triangles(t, 2)).transpose());
    box_.extend(a_.back()).extend(b_.back()).extend(c_.back());
  }
  if (m == 0) return;
  // along the box's thinnest side: the triangles a column holds are those the ray crosses
  // and those of the outline seen along it, as many as fit along the box that way
  Eigen::Index thinnest = 0;
  box_.sizes().minCoeff(&thinnest);
  frame_ = RayFrame(static_cast<int>(thinnest));
  const Vec3& ray = frame_.ray;
  std::vector<Eigen::Vector2d> lo(m), hi(m);
  std::vector<double> extents;
  extents.reserve(2 * m);
  origin_ = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector2d top = -origin_;
  crossings_.reserve(m);
  for (size_t t = 0; t < m; ++t) {
    Crossing& x = crossings_.emplace_back();
    x.a = frame_.across(a_[t]);
    x.b = frame_.across(b_[t]);
    x.c = frame_.across(c_[t]);
    x.along = Vec3(a_[t].dot(ray), b_[t].dot(ray), c_[t].dot(ray));
    x.lo = lo[t] = x.a.cwiseMin(x.b).cwiseMin(x.c);
    x.hi = hi[t] = x.a.cwiseMax(x.b).cwiseMax(x.c);
    extents.push_back(hi[t].x() - lo[t].x());
    extents.push_back(hi[t].y() - lo[t].y());
    origin_ = origin_.cwiseMin(lo[t]);
    top = top.cwiseMax(hi[t]);
  }
  cell_ = std::max(median(extents) * 0.5, 1e-9);
  const Eigen::Vector2i size = cover<2>(top - origin_, cell_, 16 * static_cast<long long>(m) + 64);
  width_ = size.x();
  height_ = size.y();
  std::vector<Eigen::Vector2i> clo(m), chi(m);
  for (size_t t = 0; t < m; ++t) {
    clo[t] = ((lo[t] - origin_) / cell_).array().floor().cast<int>().cwiseMin(size.array() - 1).matrix();
    chi[t] = ((hi[t] - origin_) / cell_).array().floor().cast<int>().cwiseMin(size.array() - 1).matrix();
  }
  bin<2>(clo, chi, size, start_, column_triangles_);
}

bool ClosedMesh::inside(const Vec3& p) const {
  if (a_.empty() || !box_.contains(p)) return false;
  const Eigen::Vector2d q = frame_.across(p);
  const double fx = std::floor((q.x() - origin_.x()) / cell_), fy = std::floor((q.y() - origin_.y()) / cell_);
  if (fx < 0 || fy < 0 || fx >= width_ || fy >= height_) return false;
  const size_t key = static_cast<size_t>(fy) * static_cast<size_t>(width_) + static_cast<size_t>(fx);
  const double height = p.dot(frame_.ray);
  int crossings = 0;
  for (int i = start_[key]; i < start_[key + 1]; ++i) {
    const Crossing& x = crossings_[static_cast<size_t>(column_triangles_[i])];
    if (q.x() < x.lo.x() || q.y() < x.lo.y() || q.x() > x.hi.x() || q.y() > x.hi.y()) continue;
    const double d1 = side(x.a, x.b, q), d2 = side(x.b, x.c, q), d3 = side(x.c, x.a, q);
    const bool hit = (d1 > 0 && d2 > 0 && d3 > 0) || (d1 < 0 && d2 < 0 && d3 < 0);
    // the crossing's height along the ray, from the barycentric weights d2, d3, d1 of a, b, c
    if (hit && (d2 * x.along.x() + d3 * x.along.y() + d1 * x.along.z()) / (d1 + d2 + d3) > height) ++crossings;
  }
  return crossings % 2 == 1;
}

void ClosedMesh::bin_spatially() const {
  const size_t m = a_.size();
  std::vector<double> extents;
  extents.reserve(m);
  std::vector<Box3> boxes(m);
  for (size_t t = 0; t < m; ++t) {
    boxes[t].extend(a_[t]).extend(b_[t]).extend(c_[t]);
    extents.push_back(boxes[t].sizes().maxCoeff());
  }
  space_cell_ = std::max(median(extents), 1e-9);
  space_size_ = cover<3>(box_.sizes(), space_cell_, 8 * static_cast<long long>(m) + 64);
  std::vector<Eigen::Vector3i> clo(m), chi(m);
  for (size_t t = 0; t < m; ++t) {
    auto index = [&](const Vec3& x) {
      return ((x - box_.min()) / space_cell_).array().floor().cast<int>().cwiseMin(space_size_.array() - 1).matrix().eval();
    };
    clo[t] = index(boxes[t].min());
    chi[t] = index(boxes[t].max());
  }
  bin<3>(clo, chi, space_size_, space_start_, space_triangles_);
}

double ClosedMesh::distance(const Vec3& p) const {
  double best = std::numeric_limits<double>::infinity();
  if (a_.empty()) return best;
  std::call_once(*space_built_, [this] { bin_spatially(); });
  // p's cell (may lie outside the grid) and the rings of cells around it: a cell r + 1 rings
  // out is at least r cells from p, so the search ends at the first ring r with best <= r cell
  Eigen::Vector3i c;
  for (int k = 0; k < 3; ++k) {
    const double f = std::floor((p[k] - box_.min()[k]) / space_cell_);
    c[k] = static_cast<int>(std::clamp(f, -1e9, 1e9));
  }
  int first = 0, last = 0;  // rings that meet the grid
  for (int k = 0; k < 3; ++k) {
    first = std::max({first, -c[k], c[k] - (space_size_[k] - 1)});
    last = std::max({last, c[k], space_size_[k] - 1 - c[k]});
  }
  auto look = [&](int x, int y, int z) {
    const size_t key = (static_cast<size_t>(z) * space_size_.y() + y) * space_size_.x() + x;
    for (int i = space_start_[key]; i < space_start_[key + 1]; ++i) {
      const size_t t = static_cast<size_t>(space_triangles_[i]);
      best = std::min(best, triangle_distance(p, a_[t], b_[t], c_[t]));
    }
  };
  for (int r = first; r <= last; ++r) {
    const int x0 = std::max(c.x() - r, 0), x1 = std::min(c.x() + r, space_size_.x() - 1);
    const int y0 = std::max(c.y() - r, 0), y1 = std::min(c.y() + r, space_size_.y() - 1);
    for (int x = x0; x <= x1; ++x) {
      for (int y = y0; y <= y1; ++y) {
        if (std::abs(x - c.x()) == r || std::abs(y - c.y()) == r) {
          for (int z = std::max(c.z() - r, 0); z <= std::min(c.z() + r, space_size_.z() - 1); ++z) look(x, y, z);
        } else {
          if (c.z() - r >= 0) look(x, y, c.z() - r);
          if (r > 0 && c.z() + r < space_size_.z()) look(x, y, c.z() + r);
        }
      }
    }
    if (best <= r * space_cell_) break;
  }
  return best;
}

ClosedMeshDepth closed_mesh_depth(const ClosedMesh& mesh, const Points& points, const Edges& edges) {
  const Eigen::Index n = points.rows();
  for (Eigen::Index e = 0; e < edges.rows(); ++e) {
    const int i = edges(e, 0), j = edges(e, 1);
    if (i < 0 || j < 0 || i >= n || j >= n) {
      throw std::out_of_range("edge " + std::to_string(e) + " names point " + std::to_string(i < 0 || i >= n ? i : j) +
                              " of " + std::to_string(n));
    }
  }
  auto depth = [&mesh](const Vec3& p) { return mesh.inside(p) ? mesh.distance(p) : 0.0; };
  auto deepest = [](Eigen::Index count, auto&& of) {
    return tbb::parallel_reduce(
        tbb::blocked_range<Eigen::Index>(0, count, 64), 0.0,
        [&](const tbb::blocked_range<Eigen::Index>& range, double d) {
          for (Eigen::Index k = range.begin(); k < range.end(); ++k) d = std::max(d, of(k));
          return d;
        },
        [](double l, double r) { return std::max(l, r); });
  };
  ClosedMeshDepth result;
  result.vertex = deepest(n, [&](Eigen::Index i) { return depth(points.row(i).transpose()); });
  result.edge = deepest(edges.rows(), [&](Eigen::Index e) {
    const Vec3 a = points.row(edges(e, 0)).transpose(), ab = points.row(edges(e, 1)).transpose() - a;
    double d = 0.0;
    for (int k = 1; k < 8; ++k) d = std::max(d, depth(a + (k / 8.0) * ab));
    return d;
  });
  return result;
}

}  // namespace simbake
