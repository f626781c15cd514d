#pragma once
// STAND-IN, to be deleted when the io branch (include/modalwatch/checkpoint.hpp,
// RecursiveEstimator::state()/restore()) is merged. It keeps the daemon's
// lifecycle (restore at start-up, periodic and final checkpoint, fingerprint
// check, atomic write, full disk) testable meanwhile, with what the estimator's
// current interface exposes: the modal parameters of each submodel (not P).
// On restore the estimator starts from these parameters with no warm-up and the
// relative P(t0); the io branch's EstimatorState restores P and the statistics too.
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "modalwatch/config.hpp"
#include "modalwatch/model.hpp"

namespace modalwatch::standin {

struct Checkpoint {
  std::uint64_t config_fingerprint = 0;
  std::int64_t last_utime = 0;  // us, newest sample included
  std::int64_t last_seq = -1;
  std::vector<ModalParameters> submodels;  // per submodel: wn, zeta, gain (rigid body: gain)
  std::vector<std::optional<ModalParameters>> baselines;
};

// Sample time, loop, controller, model structure (names, kinds, orders), forgetting.
std::uint64_t checkpoint_fingerprint(const Config& config);
// Atomic: temporary file in the same directory, fsync, rename, fsync of the directory.
// Throws std::system_error (errno) on failure; the previous checkpoint stays.
void write_checkpoint(const std::string& path, const Checkpoint& c);
// Throws InputError (missing file, bad contents).
Checkpoint read_checkpoint(const std::string& path);

}  // namespace modalwatch::standin
