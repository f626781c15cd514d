#pragma once
// Physical modes: what a fitted additive model may claim about a plant seen
// through a sampled record. An estimator (additive SRIVC, an output-error
// refinement) returns whatever lowers its cost, and on real structures that
// includes submodels that are no resonance of the plant:
//
//   - a mode above the Nyquist frequency pi/T, or one whose response over the
//     band [0, pi/T] is a constant within its uncertainty, acts as a static
//     gain: it becomes a feedthrough submodel (make_rigid_body(name, b0, 0):
//     G = b0, the same response on the band) and is named so; measured as a
//     velocity or acceleration it is b0 p^z on the band, which no submodel
//     represents, and a mode above Nyquist is left out instead;
//   - an unstable denominator (zeta <= 0, a_1 <= 0 or a_2 <= 0 for a mode) is
//     reflected into the left half plane by the estimator's stability
//     projection (section 4.7, project_stable), which keeps |A(jw)|;
//   - two modes whose natural frequencies are closer than their joint
//     uncertainty and whose gains have opposite signs cancel each other: one
//     resonance split in two. They become one mode, and the model is refitted.
//
// check_physical gives a verdict per submodel and the corrected model; the
// refit is the caller's (fit_physical for additive SRIVC).
#include <string>
#include <vector>

#include <Eigen/Core>

#include "modalwatch/model.hpp"
#include "modalwatch/record.hpp"
#include "modalwatch/srivc.hpp"

namespace modalwatch {

enum class ModeVerdict {
  physical,     // kept as fitted
  feedthrough,  // replaced by the constant b0 (kind feedthrough)
  unstable,     // projected to stability
  merged,       // removed: merged into `into`
  removed,      // left out: above Nyquist as a velocity or acceleration sensor's mode
};
const char* verdict_name(ModeVerdict verdict);

struct ModeFinding {
  std::string submodel;             // its name in the fitted model
  ModeVerdict verdict = ModeVerdict::physical;
  std::string into;                 // merged: the mode that absorbed it
  ModalParameters fitted;           // modal view as fitted (wn, zeta of A; gain b0)
  ModalParameters fitted_std;       // their standard deviations (0 when unknown)
  std::string reason;               // one line: why (numbers included)
};

struct PhysicalOptions {
  // A mode is a constant on the band when its departure from b0, relative to
  // b0 (1/A(jw) - 1), stays below this many of its standard deviations (from
  // the covariance of a_1, a_2) at every w in (0, pi/T].
  double band_sigmas = 2.0;
  // Two modes with opposite gains merge when |wn_i - wn_j| is below this many
  // joint standard deviations sqrt(var wn_i + var wn_j) and below the sum of
  // their half-power half-widths zeta_i wn_i + zeta_j wn_j (their peaks overlap).
  double merge_sigmas = 1.0;
};

struct PhysicalCheck {
  AdditiveModel model;               // the corrected model
  std::vector<ModeFinding> findings; // one per submodel of the fitted model, in its order
  bool refit = false;                // the structure changed (feedthrough, merge): refit from `model`
  bool changed() const;              // any verdict other than physical
};

// beta_covariance: covariance of the fitted model's beta (eq. 8); empty or of
// the wrong size when unknown (then only the frequency and stability rules apply).
PhysicalCheck check_physical(const AdditiveModel& fitted, const Eigen::MatrixXd& beta_covariance, double sample_time,
                             const PhysicalOptions& options = {});

// check_physical on a start model (no covariance: the frequency and stability
// rules), its findings (reasons prefixed "its start: ") appended to `findings`.
// A start mode above Nyquist is a feedthrough before any fit sees it: under
// foh a fit would otherwise move it down onto a mode of the data.
AdditiveModel physical_start(const AdditiveModel& start, double sample_time, std::vector<ModeFinding>& findings);

// fit_srivc from physical_start(initial), then check_physical on the result,
// refitted from the corrected model while the structure changes. `findings`
// collects the verdicts other than physical of every round.
FitResult fit_physical(const Record& data, const AdditiveModel& initial, const SrivcOptions& options,
                       std::vector<ModeFinding>& findings, const PhysicalOptions& physical = {});

}  // namespace modalwatch
