#pragma once
// Independent pieces of work on OpenMP's threads where the calling code is compiled with
// OpenMP (one after another where it is not), for work whose pieces may throw: the first
// exception is passed on after every piece has ended, as a loop over them would pass it
// (an exception may not leave an OpenMP region).
#include <exception>

namespace organfit {

/// Calls `piece(i)` for i in [0, count), each on whichever thread is free (pieces of
/// unequal cost: a slice's images, a view's encoding). Rethrows the first exception thrown.
template <class Piece>
void parallel_for_each(int count, Piece&& piece) {
  std::exception_ptr failed;
#pragma omp parallel for schedule(dynamic, 1)
  for (int i = 0; i < count; ++i) {
    try {
      piece(i);
    } catch (...) {
#pragma omp critical(organfit_parallel_for_each)
      if (!failed) failed = std::current_exception();
    }
  }
  if (failed) std::rethrow_exception(failed);
}

}  // namespace organfit
