#pragma once
// While alive, every OpenMP parallel region the calling thread opens runs on
// that thread alone (max-active-levels 0: no region is active).
//
// Why: CHOLMOD 3 (Debian's SuiteSparse 5) opens OpenMP regions inside its
// supernodal numeric factorisation, per supernode (zeroing and scattering
// into the supernode's panel), with a fixed num_threads(CHOLMOD_OMP_NUM_THREADS
// = 4) clause that overrides omp_set_num_threads. On a 2-core machine that is
// a team of 4 woken for a few hundred entries, thousands of times: futex
// wakes and waits take a large share of a big mesh's setup, and a "1 thread"
// run uses more than one core. The parallel work of the
// factorisation is its BLAS (OpenBLAS's own threads, set by set_threads), so
// those regions are run serially (docs/DESIGN.md, "CHOLMOD's OpenMP regions").
//
// max-active-levels is a per-thread setting in libgomp since GCC 11 (the
// calling thread's task ICVs; checked in Debian's GCC 12 libgomp), so
// solvers factorising at once in several threads do not undo each other's
// scope. An OpenMP build of OpenBLAS would run serially inside the scope too.
#include <omp.h>

namespace emu {

class SerialOpenMPScope {
 public:
  SerialOpenMPScope() : saved_(omp_get_max_active_levels()) { omp_set_max_active_levels(0); }
  ~SerialOpenMPScope() { omp_set_max_active_levels(saved_); }
  SerialOpenMPScope(const SerialOpenMPScope&) = delete;
  SerialOpenMPScope& operator=(const SerialOpenMPScope&) = delete;

 private:
  int saved_;
};

}  // namespace emu
