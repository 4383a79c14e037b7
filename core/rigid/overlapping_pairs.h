// The broad phase's pair search: every pair of boxes that overlap, in a uniform grid.
#pragma once

#include "math/types.h"

#include <array>
#include <utility>
#include <vector>

namespace simbake {

// Scratch of the broad phase's grid (see overlapping_pairs), kept so that a step allocates nothing
struct GridScratch {
  std::vector<double> sides;                  // largest side of each finite box (m)
  std::vector<std::array<long long, 6>> ranges;  // (nbox) cells a box covers, lower and
                                              // upper (x, y, z); lower x -1 for a large box
  std::vector<int> large;                     // boxes tested against every other box
  std::vector<int> cell_start;                // (ncell + 1) cell c holds
  std::vector<int> members;                   // members[cell_start[c] .. cell_start[c + 1])
  std::vector<int> filled;                    // (ncell) counting-sort cursors
};

// Every pair of overlapping boxes (a < b), sorted. The boxes are binned into a uniform grid
// whose cells are as wide as the median box (its largest side), each box into every cell it
// overlaps (a counting sort, no allocation once the scratch has grown); a pair is reported
// by the one cell that holds the lower corner of the two boxes' intersection, so exactly
// once. A box over more than kMaxCells cells (a platform, a body with a non-finite box) is
// tested against every other box instead. For boxes of similar size the cost is
// O(n + pairs); a sweep along one axis costs O(n x boxes open along it), which in a pile
// spread over the ground is a large fraction of the pile.
void overlapping_pairs(const std::vector<Box3>& boxes, GridScratch& grid, std::vector<std::pair<int, int>>& out);

}  // namespace simbake
