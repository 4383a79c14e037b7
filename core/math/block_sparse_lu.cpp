// Block LU on a graph of small dense blocks (block_sparse_lu.h).
//
// Right-looking elimination in the analysed order: node j's pivot block D_j is inverted;
// each later neighbour a's block becomes M_aj = A_aj D_j^-1, and every pair (a, b) of later
// neighbours takes the Schur update A_ab -= M_aj A_jb. The solve runs L forward (y_a -= M_aj
// y_j) and U backward (x_j = D_j^-1 (y_j - sum_b A_jb x_b)).
#include "math/block_sparse_lu.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace simbake {

namespace {

// `d` (n x n, row-major) <- its inverse, by Gauss-Jordan elimination with partial pivoting
// on a copy in `work`; false if a pivot is zero or not finite
bool invert_in_place(double* d, int n, std::vector<double>& work) {
  work.assign(d, d + n * n);
  double* s = work.data();
  for (int i = 0; i < n * n; ++i) d[i] = 0.0;
  for (int i = 0; i < n; ++i) d[i * n + i] = 1.0;
  for (int col = 0; col < n; ++col) {
    int pivot = col;
    for (int r = col + 1; r < n; ++r) {
      if (std::abs(s[r * n + col]) > std::abs(s[pivot * n + col])) pivot = r;
    }
    const double p = s[pivot * n + col];
    if (!(std::abs(p) > 0.0) || !std::isfinite(p)) return false;
    if (pivot != col) {
      for (int c = 0; c < n; ++c) {
        std::swap(s[pivot * n + c], s[col * n + c]);
        std::swap(d[pivot * n + c], d[col * n + c]);
      }
    }
    const double inverse = 1.0 / p;
    for (int c = 0; c < n; ++c) {
      s[col * n + c] *= inverse;
      d[col * n + c] *= inverse;
    }
    for (int r = 0; r < n; ++r) {
      const double f = s[r * n + col];
      if (r == col || f == 0.0) continue;
      for (int c = 0; c < n; ++c) {
        s[r * n + c] -= f * s[col * n + c];
        d[r * n + c] -= f * d[col * n + c];
      }
    }
  }
  for (int i = 0; i < n * n; ++i) {
    if (!std::isfinite(d[i])) return false;
  }
  return true;
}

void insert_sorted(std::vector<int>& set, int value) {
  const auto at = std::lower_bound(set.begin(), set.end(), value);
  if (at == set.end() || *at != value) set.insert(at, value);
}

void erase_sorted(std::vector<int>& set, int value) {
  const auto at = std::lower_bound(set.begin(), set.end(), value);
  if (at != set.end() && *at == value) set.erase(at);
}

}  // namespace

void BlockSparseLU::analyze(const std::vector<int>& sizes, const std::vector<std::pair<int, int>>& adjacent) {
  const int n = static_cast<int>(sizes.size());
  sizes_ = sizes;
  offsets_.assign(n + 1, 0);
  for (int k = 0; k < n; ++k) offsets_[k + 1] = offsets_[k] + sizes[k];
  std::vector<std::vector<int>> graph(n);
  for (const auto& [a, b] : adjacent) {
    if (a == b) continue;
    graph[a].push_back(b);
    graph[b].push_back(a);
  }
  int original = 0;
  for (auto& neighbours : graph) {
    std::sort(neighbours.begin(), neighbours.end());
    neighbours.erase(std::unique(neighbours.begin(), neighbours.end()), neighbours.end());
    original += static_cast<int>(neighbours.size());
  }
  original /= 2;

  // minimum degree: the node with the fewest neighbours left goes next, and they become a
  // clique (the fill); graph[k] holds only the neighbours not yet eliminated
  std::vector<char> done(n, 0);
  std::vector<std::vector<int>> later_nodes(n);
  order_.clear();
  int filled = 0;
  for (int step = 0; step < n; ++step) {
    int next = -1;
    for (int k = 0; k < n; ++k) {
      if (!done[k] && (next < 0 || graph[k].size() < graph[next].size())) next = k;
    }
    done[next] = 1;
    order_.push_back(next);
    later_nodes[next] = graph[next];
    filled += static_cast<int>(graph[next].size());
    for (int a : graph[next]) {
      erase_sorted(graph[a], next);
      for (int b : graph[next]) {
        if (b != a) insert_sorted(graph[a], b);
      }
    }
    graph[next].clear();
  }
  fill_ = filled - original;

  // every block of the filled pattern, node by node, by neighbour
  entries_.assign(n, {});
  for (int k = 0; k < n; ++k) {
    entries_[k].push_back({k, 0});
    for (int a : later_nodes[k]) {
      entries_[k].push_back({a, 0});
      entries_[a].push_back({k, 0});
    }
  }
  int total = 0;
  diagonal_.assign(n, 0);
  for (int k = 0; k < n; ++k) {
    std::sort(entries_[k].begin(), entries_[k].end(), [](const Entry& x, const Entry& y) { return x.node < y.node; });
    for (Entry& e : entries_[k]) {
      e.offset = total;
      total += sizes[k] * sizes[e.node];
      if (e.node == k) diagonal_[k] = e.offset;
    }
  }
  values_.assign(total, 0.0);

  later_.assign(n, {});
  updates_.assign(n, {});
  for (int j = 0; j < n; ++j) {
    for (int a : later_nodes[j]) later_[j].push_back({a, static_cast<int>(block(a, j) - values_.data()),
                                                      static_cast<int>(block(j, a) - values_.data())});
    for (const Later& a : later_[j]) {
      for (const Later& b : later_[j]) {
        updates_[j].push_back({static_cast<int>(block(a.node, b.node) - values_.data()), a.lower, b.upper,
                               sizes[a.node], sizes[b.node], sizes[j]});
      }
    }
  }
}

double* BlockSparseLU::block(int a, int b) {
  for (const Entry& e : entries_[a]) {
    if (e.node == b) return values_.data() + e.offset;
  }
  return nullptr;
}

const double* BlockSparseLU::block(int a, int b) const {
  return const_cast<BlockSparseLU*>(this)->block(a, b);
}

void BlockSparseLU::set_zero() { std::fill(values_.begin(), values_.end(), 0.0); }

void BlockSparseLU::set_unit_row(int a, int r) {
  for (const Entry& e : entries_[a]) {
    const int cols = sizes_[e.node];
    double* row = values_.data() + e.offset + r * cols;
    std::fill(row, row + cols, 0.0);
    if (e.node == a) row[r] = 1.0;
  }
}

bool BlockSparseLU::factorize() {
  double* v = values_.data();
  for (int j : order_) {
    const int n = sizes_[j];
    if (!invert_in_place(v + diagonal_[j], n, scratch_)) return false;
    const double* inverse = v + diagonal_[j];
    // M_aj = A_aj D_j^-1, in place
    for (const Later& a : later_[j]) {
      const int rows = sizes_[a.node];
      double* m = v + a.lower;
      scratch_.assign(m, m + rows * n);
      for (int r = 0; r < rows; ++r) {
        for (int c = 0; c < n; ++c) {
          double sum = 0.0;
          for (int k = 0; k < n; ++k) sum += scratch_[r * n + k] * inverse[k * n + c];
          m[r * n + c] = sum;
        }
      }
    }
    // A_ab -= M_aj A_jb
    for (const Update& u : updates_[j]) {
      double* target = v + u.target;
      const double* lower = v + u.lower;
      const double* upper = v + u.upper;
      for (int r = 0; r < u.rows; ++r) {
        for (int c = 0; c < u.cols; ++c) {
          double sum = 0.0;
          for (int k = 0; k < u.inner; ++k) sum += lower[r * u.inner + k] * upper[k * u.cols + c];
          target[r * u.cols + c] -= sum;
        }
      }
    }
  }
  return true;
}

void BlockSparseLU::solve(double* b) const {
  const double* v = values_.data();
  // L y = b: forward, y_a -= M_aj y_j
  for (int j : order_) {
    const double* yj = b + offsets_[j];
    const int n = sizes_[j];
    for (const Later& a : later_[j]) {
      const double* m = v + a.lower;
      double* ya = b + offsets_[a.node];
      for (int r = 0; r < sizes_[a.node]; ++r) {
        double sum = 0.0;
        for (int k = 0; k < n; ++k) sum += m[r * n + k] * yj[k];
        ya[r] -= sum;
      }
    }
  }
  // U x = y: backward, x_j = D_j^-1 (y_j - sum_b A_jb x_b)
  double t[64];
  std::vector<double> big;
  for (auto it = order_.rbegin(); it != order_.rend(); ++it) {
    const int j = *it;
    const int n = sizes_[j];
    double* yj = b + offsets_[j];
    double* rest = t;
    if (n > 64) {
      big.resize(n);
      rest = big.data();
    }
    for (int r = 0; r < n; ++r) rest[r] = yj[r];
    for (const Later& a : later_[j]) {
      const double* u = v + a.upper;
      const double* xa = b + offsets_[a.node];
      const int cols = sizes_[a.node];
      for (int r = 0; r < n; ++r) {
        double sum = 0.0;
        for (int k = 0; k < cols; ++k) sum += u[r * cols + k] * xa[k];
        rest[r] -= sum;
      }
    }
    const double* inverse = v + diagonal_[j];
    for (int r = 0; r < n; ++r) {
      double sum = 0.0;
      for (int k = 0; k < n; ++k) sum += inverse[r * n + k] * rest[k];
      yj[r] = sum;
    }
  }
}

}  // namespace simbake
