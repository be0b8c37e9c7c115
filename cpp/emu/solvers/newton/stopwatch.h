#pragma once
// Wall-clock time for solve statistics.
#include <chrono>

namespace emu {
using Clock = std::chrono::steady_clock;
inline double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

/// Adds the seconds of its scope to an accumulator (per-phase solve times).
class ScopedSeconds {
 public:
  explicit ScopedSeconds(double& total) : total_(total), t0_(Clock::now()) {}
  ~ScopedSeconds() { total_ += seconds_since(t0_); }
  ScopedSeconds(const ScopedSeconds&) = delete;
  ScopedSeconds& operator=(const ScopedSeconds&) = delete;

 private:
  double& total_;
  Clock::time_point t0_;
};
}  // namespace emu
