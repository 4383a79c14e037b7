// Islands of an impulse stage: bodies linked through the stage's items (collision pairs with
// points inside, or contact points) form islands that share no movable body, so each island
// is swept on its own, in parallel, with the same bits on any number of threads. The ground
// and kinematic bodies, which no impulse moves, link nothing. Union-find with path halving.
#pragma once

#include "rigid/rigid_body.h"

#include <array>
#include <vector>

namespace simbake {

// What impulses leave behind, per island (or per serial stage): the bodies whose
// candidates are stale, and how many impulses were applied
struct ImpulseLog {
  std::vector<int> stale;
  long long impulses = 0;
};
// The islands of an impulse stage (see rigid/contacts.cpp), rebuilt by each stage from its
// items: the pairs with samples inside (collisions) or the contacts
struct IslandScratch {
  int count = 0;
  std::vector<std::array<int, 2>> links;    // (nitem) bodies of each item; -1: in no island
  std::vector<int> parent;                  // (nbody) union-find through the links
  std::vector<int> index;                   // (nbody) island of a root body, else -1
  std::vector<int> of_body;                 // (nbody) island of each body, -1 when unlinked
  std::vector<int> of_item;                 // (nitem) island of each item, or -1
  std::vector<int> item_start;              // (count + 1) island k's items are
  std::vector<int> items;                   //   items[item_start[k] .. item_start[k + 1])
  std::vector<int> filled;                  // (count) counting-sort cursors
  std::vector<int> order;                   // (npair) collisions: a sweep's shuffled pairs
  std::vector<int> by_sweep;                // (sweeps x nitem) collisions: island k's pairs
                                            //   in sweep s at s nitem + item_start[k] ..
  std::vector<int> body_start;              // (count + 1) island k's bodies with a level,
  std::vector<int> bodies;                  //   by level, likewise (shock propagation)
  std::vector<std::vector<int>> by_level;   // (count) island k's contacts by level
  std::vector<ImpulseLog> logs;             // (count)
};

// Union-find over n bodies: every body its own set
void reset_sets(std::vector<int>& parent, int n);
// The root of i's set (path halving)
int set_root(std::vector<int>& parent, int i);

// The islands of islands.links (item k links bodies a and b, b < 0 the ground; a < 0: item k
// is in no island) over the bodies `defs`, numbered in the order of their first item, each
// with its items in order; their logs start empty. Allocates nothing once the scratch has grown
void find_islands(const std::vector<RigidBodyDef>& defs, IslandScratch& islands);

}  // namespace simbake
