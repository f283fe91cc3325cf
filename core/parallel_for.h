// ParallelFor: independent work items (frames of a take, images of a rig) spread over a few
// threads. Each index in [0, count) runs exactly once, in no particular order, on one of
// `threads` threads (the calling thread is one of them); 0 threads means the machine's cores.
// After the first error no further indices are started, and the error returned is the one of
// the lowest failing index among those that ran, with that index named by the caller's body.
#pragma once

#include <functional>

#include "core/status.h"

namespace facedyn {

// The threads ParallelFor would use: `threads` (0: hardware concurrency, at least 1), never more
// than `count` (and at least 1).
int ParallelThreadCount(int threads, int count);

Status ParallelFor(int count, int threads, const std::function<Status(int index)>& body);

}  // namespace facedyn
