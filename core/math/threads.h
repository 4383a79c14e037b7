// Work on at most `threads` of the machine's CPUs (0: all of them): the core's parallel loops
// run inside such an arena, so `--threads N` holds for every stage that the world runs.
#pragma once

#include <tbb/info.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <utility>

namespace simbake {

template <class F>
auto on_threads(int threads, F&& f) {
  // (more threads than the machine has would only be refused by TBB, with a warning on
  // stderr: the results are the same bits on any count, so the arena takes what there is)
  tbb::task_arena arena(threads > 0 ? std::min(threads, tbb::info::default_concurrency()) : tbb::task_arena::automatic);
  return arena.execute(std::forward<F>(f));
}

}  // namespace simbake
