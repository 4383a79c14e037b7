#include "levelset/deforming_surface.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace simbake {

DeformingSurface::DeformingSurface(const Points& vertices, SignedDistancePtr shape, double time)
    : start_(vertices), end_(vertices), velocity_(Points::Zero(vertices.rows(), 3)), start_shape_(shape),
      end_shape_(shape), start_time_(time) {
  if (vertices.rows() == 0) throw std::invalid_argument("a deforming surface needs vertices");
  bin();
}

void DeformingSurface::set_frame(const Points& vertices, SignedDistancePtr shape, double time, double duration) {
  if (vertices.rows() != end_.rows()) {
    throw std::invalid_argument("a deforming surface keeps its " + std::to_string(end_.rows()) + " vertices, got " +
                                std::to_string(vertices.rows()));
  }
  if (!(duration > 0.0)) throw std::invalid_argument("a deforming surface's frame needs a duration > 0");
  start_ = end_;
  end_ = vertices;
  velocity_ = (end_ - start_) / duration;
  start_shape_ = end_shape_;
  end_shape_ = std::move(shape);
  start_time_ = time;
  duration_ = duration;
  bin();
}

double DeformingSurface::blend(double time) const {
  if (!(duration_ > 0.0)) return 1.0;
  return std::clamp((time - start_time_) / duration_, 0.0, 1.0);
}

SignedDistancePtr DeformingSurface::shape_at(double s) const {
  if (s >= 1.0 || start_shape_ == end_shape_) return end_shape_;
  return std::make_shared<BlendedDistance>(start_shape_, end_shape_, s);
}

double DeformingSurface::reach(const Vec3& center) const {
  double r = 0.0;
  for (Eigen::Index k = 0; k < end_.rows(); ++k) {
    r = std::max({r, (start_.row(k).transpose() - center).norm(), (end_.row(k).transpose() - center).norm()});
  }
  return r;
}

double DeformingSurface::fastest_in(const Box3& box) const {
  double fastest = 0.0;
  for (Eigen::Index k = 0; k < end_.rows(); ++k) {
    const Vec3 a = start_.row(k).transpose(), b = end_.row(k).transpose();
    if (box.intersects(Box3(a.cwiseMin(b), a.cwiseMax(b)))) {
      fastest = std::max(fastest, velocity_.row(k).norm());
    }
  }
  return fastest;
}

// Cells of about the mean distance between neighbouring vertices: the bounding box's volume
// shared among the vertices (at most kCellsPerVertex cells a vertex: a flat surface's box has
// next to no volume), counted into a flat array of cells (a cell's vertices in index order)
void DeformingSurface::bin() {
  constexpr double kCellsPerVertex = 64.0;
  const Vec3 lo = end_.colwise().minCoeff().transpose(), hi = end_.colwise().maxCoeff().transpose();
  const Vec3 size = hi - lo;
  const double volume = std::max(size.prod(), std::pow(std::max(size.maxCoeff(), 1e-6), 3) * 1e-6);
  const double n = static_cast<double>(end_.rows());
  cell_ = std::max(std::cbrt(volume / n), 1e-6);
  const auto cells = [&] { return ((size / cell_).array().floor() + 2.0).prod(); };
  while (cells() > kCellsPerVertex * n + 64.0) cell_ *= 1.25;
  corner_ = (lo / cell_).array().floor().cast<int>().matrix();
  extent_ = (hi / cell_).array().floor().cast<int>().matrix() - corner_ + Eigen::Vector3i::Ones();
  const auto index = [&](const Eigen::Vector3i& c) { return (c.z() * extent_.y() + c.y()) * extent_.x() + c.x(); };
  cell_start_.assign(static_cast<size_t>(extent_.prod()) + 1, 0);
  std::vector<int> cell(end_.rows());
  for (Eigen::Index k = 0; k < end_.rows(); ++k) {
    cell[k] = index(cell_of(end_.row(k).transpose()));
    ++cell_start_[cell[k] + 1];
  }
  for (size_t c = 1; c < cell_start_.size(); ++c) cell_start_[c] += cell_start_[c - 1];
  cell_vertex_.resize(end_.rows());
  std::vector<int> next(cell_start_.begin(), cell_start_.end() - 1);
  for (Eigen::Index k = 0; k < end_.rows(); ++k) cell_vertex_[next[cell[k]]++] = static_cast<int>(k);
}

// (relative to corner_)
Eigen::Vector3i DeformingSurface::cell_of(const Vec3& p) const {
  return (p / cell_).array().floor().cast<int>().matrix() - corner_;
}

// The nearest of the vertices in the 3 x 3 x 3 cells about p's; none there, the nearest of
// all (p far from the surface), found ring by ring of cells outward: a cell r cells from p's
// (in the largest of its offsets) is at least r - 1 cells from p, so the search stops at the
// first ring that cannot hold a vertex as near as the nearest so far (ties: the lower index)
Vec3 DeformingSurface::velocity_at(const Vec3& p) const {
  int best = -1;
  double nearest = std::numeric_limits<double>::infinity();
  const Eigen::Vector3i c = cell_of(p);
  const auto visit = [&](int x, int y, int z) {
    const int cell = (z * extent_.y() + y) * extent_.x() + x;
    for (int i = cell_start_[cell]; i < cell_start_[cell + 1]; ++i) {
      const int k = cell_vertex_[i];
      const double d = (end_.row(k).transpose() - p).squaredNorm();
      if (d < nearest || (d == nearest && k < best)) nearest = d, best = k;
    }
  };
  // the cells of the ring r cells from p's (r = 0: p's own cell), those in the grid
  const auto ring = [&](int r) {
    const Eigen::Vector3i lo = (c.array() - r).max(0).matrix(), hi = (c.array() + r).min(extent_.array() - 1).matrix();
    for (int z = lo.z(); z <= hi.z(); ++z) {
      for (int y = lo.y(); y <= hi.y(); ++y) {
        if (std::abs(z - c.z()) == r || std::abs(y - c.y()) == r) {
          for (int x = lo.x(); x <= hi.x(); ++x) visit(x, y, z);
        } else {
          if (c.x() - r >= 0 && c.x() - r < extent_.x()) visit(c.x() - r, y, z);
          if (r > 0 && c.x() + r >= 0 && c.x() + r < extent_.x()) visit(c.x() + r, y, z);
        }
      }
    }
  };
  ring(0);
  ring(1);
  if (best >= 0) return vertex_velocity(best);
  // (the rings before `first` and past `last` hold no cell of the grid)
  const Eigen::Array3i below = -c.array(), above = c.array() - extent_.array() + 1;
  const int first = std::max(2, below.max(above).max(0).maxCoeff());
  const int last = below.abs().max(above.abs()).maxCoeff();
  for (int r = first; r <= last; ++r) {
    // (a hundredth of a cell's margin for p's cell rounded at its border)
    if (best >= 0 && std::pow((r - 1.01) * cell_, 2) > nearest) break;
    ring(r);
  }
  return vertex_velocity(best);
}

// Least squares of v_k = A x_k + c over the vertices: with y_k = (x_k - mean) the centred
// positions, A = (sum v_k y_k^T) (sum y_k y_k^T)^-1 and c = mean(v) - A mean(x)
void DeformingSurface::affine_motion(double s, Mat3& A, Vec3& c) const {
  const Eigen::Index n = end_.rows();
  Vec3 mean_x = Vec3::Zero(), mean_v = Vec3::Zero();
  for (Eigen::Index k = 0; k < n; ++k) {
    mean_x += vertex(static_cast<int>(k), s);
    mean_v += vertex_velocity(static_cast<int>(k));
  }
  mean_x /= static_cast<double>(n);
  mean_v /= static_cast<double>(n);
  Mat3 vy = Mat3::Zero(), yy = Mat3::Zero();
  for (Eigen::Index k = 0; k < n; ++k) {
    const Vec3 y = vertex(static_cast<int>(k), s) - mean_x;
    vy += (vertex_velocity(static_cast<int>(k)) - mean_v) * y.transpose();
    yy += y * y.transpose();
  }
  // (a flat or degenerate surface: the pseudo-inverse keeps the directions it spans)
  Eigen::CompleteOrthogonalDecomposition<Mat3> solve(yy);
  A = vy * solve.pseudoInverse();
  c = mean_v - A * mean_x;
}

}  // namespace simbake
