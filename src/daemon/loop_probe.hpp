#pragma once
// A test hook into the estimation loop, outside the public API: tests reach it
// with the source tree on their include path. Attach before Daemon::start().
namespace modalwatch {

class Daemon;

// warmed_up(): on the estimation thread, at the start of the first tick after
// the estimator's warm-up is over (its fit applied and the input held meanwhile
// worked off) and at least one snapshot went out. exiting(): after the loop's
// last tick (its final drain included), each time the loop thread ends (stop,
// and the pauses of reload and checkpoints).
class LoopProbe {
 public:
  virtual ~LoopProbe() = default;
  virtual void warmed_up() = 0;
  virtual void exiting() = 0;
  // On the fitter thread, before the warm-up fit runs (a test makes the fit slow here).
  virtual void warmup_fit_running() {}
};

// Daemon's friend, so that the public header need not name the probe.
struct DaemonAccess {
  static void attach_loop_probe(Daemon& daemon, LoopProbe& probe);
};

// The probe must outlive the daemon's threads. Throws std::logic_error once started.
inline void attach_loop_probe(Daemon& daemon, LoopProbe& probe) { DaemonAccess::attach_loop_probe(daemon, probe); }

}  // namespace modalwatch
