// A square matrix of small dense blocks on a graph, factored in place as A = L U.
//
// The joints stage's system (rigid/joints.cpp) has one node per joint (its rows) and a block
// between two joints that share a body. Eliminated in a minimum-degree order, a tree of
// joints (a chain, a ragdoll) makes no fill at all: a leaf joint's remaining neighbours are
// the joints on its parent body, which are neighbours of each other already (Baraff,
// "Linear-time dynamics using Lagrange multipliers", SIGGRAPH 1996, makes the same
// observation on the bodies-and-joints graph). So the factorization costs the sum over nodes
// of (size x later neighbours)^2-ish, linear in the chain's length; loops (a glued wall)
// fill in only as much as their elimination needs. Pivoting is within blocks only (each
// pivot block is inverted with partial pivoting), which is stable for the nearly symmetric
// positive definite systems J M^-1 J^T + regularization it is given.
//
// Use: analyze(sizes, adjacent) once per pattern; then, as often as the values change,
// set_zero(), fill blocks through block(a, b), factorize(), solve(b).
#pragma once

#include <utility>
#include <vector>

namespace simbake {

class BlockSparseLU {
 public:
  // Node k has sizes[k] rows and columns; blocks (a, b) and (b, a) may be nonzero for each
  // pair in `adjacent` (a != b, any order, repeats allowed), (k, k) for every k. Finds the
  // elimination order (minimum degree, ties to the lowest index) and the fill it makes
  void analyze(const std::vector<int>& sizes, const std::vector<std::pair<int, int>>& adjacent);

  int node_count() const { return static_cast<int>(sizes_.size()); }
  int size() const { return offsets_.empty() ? 0 : offsets_.back(); }  // rows in all
  int offset(int node) const { return offsets_[node]; }               // node's first row
  int node_size(int node) const { return sizes_[node]; }
  int fill_blocks() const { return fill_; }                           // pairs the order added
  const std::vector<int>& order() const { return order_; }

  // Block (a, b), row-major sizes[a] x sizes[b], when a == b or (a, b) is in the (filled)
  // pattern; else nullptr
  double* block(int a, int b);
  const double* block(int a, int b) const;
  void set_zero();
  // Row r of node a becomes the identity's: zero in every block, 1 on the diagonal
  void set_unit_row(int a, int r);
  // Every value, to keep and put back (a factorization overwrites them)
  const std::vector<double>& values() const { return values_; }
  double* data() { return values_.data(); }
  void set_values(const std::vector<double>& values) { values_ = values; }

  // Factors in place; false if a pivot block is singular or not finite
  bool factorize();
  // b <- A^-1 b (size() entries, node k's at offset(k)); after factorize()
  void solve(double* b) const;

 private:
  struct Entry {
    int node;    // the other node
    int offset;  // of block (this, node) in values_
  };
  // node j's elimination: its later neighbours' blocks and the Schur updates they take
  struct Later {
    int node, lower, upper;  // neighbour a, offsets of (a, j) and (j, a)
  };
  struct Update {
    int target, lower, upper, rows, cols, inner;  // (a, b) -= (a, j) (j, b): offsets and sizes
  };

  std::vector<int> sizes_, offsets_;
  std::vector<std::vector<Entry>> entries_;   // (n) each node's blocks, by neighbour, self included
  std::vector<int> order_;                    // elimination order
  std::vector<int> diagonal_;                 // (n) offset of block (k, k)
  std::vector<std::vector<Later>> later_;     // (n) by node
  std::vector<std::vector<Update>> updates_;  // (n) by node
  std::vector<double> values_;
  std::vector<double> scratch_;
  int fill_ = 0;
};

}  // namespace simbake
