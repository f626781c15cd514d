#pragma once
// Offline estimators: SRIVC (K = 1) and additive SRIVC by block-coordinate
// descent (Algorithm 0 of the paper with the SRIVC iterations of eq. (17) per
// block; the paper's references gonzalez2023parsimonious and
// gonzalez2023identification), in open and closed loop (instrument from
// z = S_uo(q) r, eq. 29), with rigid-body submodels (eqs. 32-33) and stability
// projection at every iteration. These seed the recursive estimator.
#include <string>
#include <vector>

#include <Eigen/Core>

#include "modalwatch/model.hpp"
#include "modalwatch/prefilter.hpp"
#include "modalwatch/record.hpp"
#include "modalwatch/transfer_function.hpp"

namespace modalwatch {

// The intersample behaviour of y assumed when the configuration names none,
// by the batch fits (`fit`, `diagnose`) of their start and by the recursive
// estimator (`track`, the daemon, its warm-up fit) of the configured modes:
// foh when a mode lies between kFohFromFraction of the sampling rate and the
// Nyquist frequency, else zoh. The sampled output of a mode is not held, and
// the faster the mode the more zoh's staircase misplaces it: above about 0.3
// fs zoh biases even a fit from the true modes (wn by percents, zeta by tens
// of percent). From 0.1 fs up, a lightly damped mode can take a fit from a
// start a few % off: a closed loop with its fastest mode at 0.12 fs (zeta
// 0.008) fitted 8.6 % with zoh, its warm-up fit gave that mode no gain and the
// recursion lost another mode (6 false flags in 1.2 h of healthy data); with
// foh the fit reaches 96 % and every mode is followed without a reset. Below
// 0.1 fs zoh and foh give the same estimates on the scenario bank, and zoh
// costs a third of the instructions per sample (one discretisation serves a
// mode's four filters). A start mode above Nyquist is left out of the rule:
// `fit` and `diagnose` make it a feedthrough before fitting (physical_start),
// since under foh a fit would move it down onto a mode of the data (a start
// mode at 1e5 Hz beside modes up to 0.1 fs at 100 Hz took the 10 Hz mode's place).
inline constexpr double kFohFromFraction = 0.1;
Hold default_output_hold(const AdditiveModel& start, double sample_time);

struct SrivcOptions {
  int max_iterations = 100;      // block-coordinate cycles over all submodels
  int srivc_per_block = 1;       // SRIVC refinements of one submodel per cycle
  double tolerance = 1e-10;      // on the relative change of beta per cycle
  Hold output_hold = Hold::zoh;  // intersample behaviour assumed for y in the prefilters
  // ... and for the input, open loop only: zoh for an input the plant receives
  // held (a DAC), foh for a measured band-limited one (a shaker's force). Near
  // Nyquist the two differ by up to half a sample of delay, which a zoh fit of a
  // band-limited record puts on its fastest modes (the flexible structure of
  // the README: with zoh no block stays on its 397, 417 or 467 Hz peak).
  Hold input_hold = Hold::zoh;
  bool stability_projection = true;
  // Trust region: a block's natural frequency moves by at most this factor per
  // iteration (1 or less: no limit). Keeps blocks on their own modes from a rough start.
  double max_frequency_step = 1.25;
  // For K >= 2 resonant modes, also start from the partial fractions of an
  // unfactored (K = 1) SRIVC fit and keep the start with the lower output error.
  bool unfactored_start = true;
  // Closed loop: u = C_d(q)(r - y); the record must carry r.
  bool closed_loop = false;
  DiscreteTransferFunction controller;
  // When the cycles end without converging, return the cycle of least output
  // error if it is at least 1 % below the last one's (FitResult::best_iteration).
  // The batch tools (`fit`, `diagnose`) ask for it; the recursive estimator's
  // warm-up fit and refits keep the last cycle.
  bool best_cycle = false;
  // Samples at the start of the record that drive the prefilters and the model's
  // simulation but stay out of the estimate (eq. 8), the output error and the
  // covariance: a window cut from a running plant, whose model output, started
  // from rest, needs them to catch up (`modalwatch fit --from`).
  Eigen::Index settle_samples = 0;
  // With settle_samples: the model's state at the fitted part's start is
  // estimated with it, not taken from its simulation from rest. A window whose
  // settling part holds a change of the plant (a refit after a divergence)
  // begins its fitted part with the changed plant's free response from a state
  // the simulation never had. Each cycle's regressions see the fitted part's
  // output less the model's free response that best explains its output
  // error there, and the settling part's output as the model's own from rest,
  // so that the prefilters enter the fitted part on the model's trajectory,
  // not on the old plant's (FitResult::simulated stays the one from rest).
  bool free_initial_state = false;
  // Per submodel (empty: none frozen): a frozen submodel keeps its given
  // parameters, and its simulated output is subtracted from the data as any
  // other's (eq. 15); only the other blocks are estimated. The covariance is
  // still over every block (with the frozen ones as given).
  std::vector<bool> frozen;
};

struct FitResult {
  AdditiveModel model;
  // Covariance of beta (eq. 8), sigma^2 times the IV sandwich
  // J^{-1} (sum psi_hat psi_hat^T) J^{-T}; in open loop this is sigma^2 P.
  Eigen::MatrixXd covariance;
  double noise_variance = 0.0;  // sigma^2 of the output error
  double fit_percent = 0.0;     // 100 (1 - ||y - y_hat|| / ||y - mean(y)||)
  int iterations = 0;
  bool converged = false;
  // Not converged: the cycle whose model is returned, the one of least output
  // error, when it is not the last (0 otherwise).
  int best_iteration = 0;
  int projections = 0;                 // stability projections applied
  int damped_steps = 0;                // iterations shortened by the frequency trust region
  std::string start = "configured";    // which start won: "configured" or "unfactored"
  // Closed loop: the returned model, in the loop with the controller, diverges
  // on the record (a gain of the wrong sign makes positive feedback), so its
  // instruments overflow, and the covariance and the identifiability below
  // are not defined.
  bool unstable_loop = false;
  std::vector<double> change_history;  // relative change of beta per cycle
  Eigen::VectorXd simulated;           // y_hat: the model's output on the record
  // Identifiability: the condition number of the instruments' correlation
  // matrix (sum psi_hat psi_hat^T with unit diagonal). A reference with too few
  // frequencies (n sinusoids give 2n real equations) leaves it singular, and the
  // covariance above then only describes the determined directions. Above
  // kPoorlyDetermined the record does not determine every parameter;
  // weakest_direction (unit length, over beta) is the combination it leaves open.
  static constexpr double kPoorlyDetermined = 1e8;
  double information_condition = 0.0;
  Eigen::VectorXd weakest_direction;

  // Covariance block of submodel i.
  Eigen::MatrixXd theta_covariance(int i) const;
};

// Several measured inputs: each block's prefiltered regressors and
// instruments come from its submodel's input (Submodel::input indexes
// Record::input), the other blocks' simulated outputs are subtracted as for one
// input (eq. 15). Submodels that share poles (Submodel::poles_of) are one block:
// its regression has A's coefficients once and each member's B on its own
// input, and the covariance counts the shared A once (FitResult::covariance
// over beta repeats it per member, fully correlated). Throws
// std::invalid_argument on a record too short for the number of parameters, a
// closed-loop fit without a reference or controller or with input_hold foh, a
// submodel on an input the record lacks, a closed loop with submodels on
// several inputs (the controller gives one u), or a poles_of that pole_groups refuses.
FitResult fit_srivc(const Record& data, const AdditiveModel& initial, const SrivcOptions& options);

// Output of the model on the record: open loop, the simulated sum of submodels
// driven by u (ZOH); closed loop with simulate_loop, the noise-free loop driven by r.
Eigen::VectorXd simulate_model(const AdditiveModel& model, const Eigen::VectorXd& u, double T);
// The same with every submodel driven by its own input of the record (open loop).
Eigen::VectorXd simulate_model(const AdditiveModel& model, const Record& data, Hold input_hold = Hold::zoh);
// Noise-free closed loop with the known controller: returns z = S_uo(q) r (the
// instrument input, eq. 29) and the loop output.
void simulate_loop(const AdditiveModel& model, const DiscreteTransferFunction& controller, const Eigen::VectorXd& r,
                   double T, Eigen::VectorXd& z, Eigen::VectorXd& y);

double fit_percent(const Eigen::VectorXd& y, const Eigen::VectorXd& y_hat);

// The record as `model` started in the state that best explains its output
// after `settle_samples` sees it (SrivcOptions::free_initial_state): impulses
// on each input over the settling part, one per state of the submodels on it,
// whose responses fit the model's output error after it (least squares), and
// the settling part's output the model's own. A recursion that runs its
// filters over it ends in that state, where over the record itself it would
// carry the plant's response to whatever the settling part held. The record
// unchanged for no settling part or one too short for the states.
Record started_in_state(const Record& data, const AdditiveModel& model, Eigen::Index settle_samples,
                        Hold input_hold = Hold::zoh);

}  // namespace modalwatch
