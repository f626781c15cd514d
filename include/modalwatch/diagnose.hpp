#pragma once
// Closing the loop with measured data: fit the configured additive model, test
// the residual, trace it to an effect the model lacks, add the best effect,
// refit, and repeat while the residual tests still fail and an effect lowers
// the validation error significantly beyond what a refit of the model without
// it gives (its credit: a refit alone may only continue a refinement the
// previous fit left unfinished).
//
// The augmented model is the additive model of eq. (5) with the effects of
// include/modalwatch/effects.hpp around it (input offset, delay, Coulomb and
// cubic branches at its input; output offset and drift at its output), the
// structure `simulate` makes records with. Only the modes and rigid bodies are
// carried by the recursive estimator (`track`) and the daemon; the effects are
// fitted by `diagnose` alone.
#include <functional>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "modalwatch/effects.hpp"
#include "modalwatch/model.hpp"
#include "modalwatch/physical.hpp"
#include "modalwatch/prefilter.hpp"
#include "modalwatch/record.hpp"
#include "modalwatch/spectra.hpp"
#include "modalwatch/transfer_function.hpp"

namespace modalwatch {

// complex_modes: every mode's numerator b0 + b1 p (complex residues: damping
// that is not proportional, a sensor not collocated with the actuator, a lag
// the band sees as phase); feedthrough: a constant beside the modes (the modes
// above the band seen as their static gain, modal analysis' upper residual).
enum class EffectKind { mode, rigid_body, offset, drift, delay, coulomb, cubic, complex_modes, feedthrough };
const char* effect_name(EffectKind kind);
std::vector<EffectKind> all_effects();

// The effects of a model, and which of them it carries: a flag says the
// parameter is part of the model (and fitted); its value may still be small.
// A value without its flag is not used. A delay is part of the model when > 0.
struct ModelEffects : PlantEffects {
  bool output_offset_on = false, input_offset_on = false, drift_on = false, coulomb_on = false, cubic_on = false;
  int n_params() const;  // continuous parameters plus one for a delay
  bool operator==(const ModelEffects&) const = default;
};

struct AugmentedModel {
  AdditiveModel linear;
  ModelEffects effects;
  int n_params() const { return linear.n_beta() + effects.n_params(); }
};

// How a model is run on a record. Closed loop: u = C_d(q)(r - y_sim) + u_ext with
// u_ext = u - C_d(q)(r - y) from the measured signals, the excitation the loop
// adds besides the controller (zero for a record made by this controller; an
// injected pulse or a two-degree-of-freedom law otherwise).
struct LoopSpec {
  bool closed = false;
  DiscreteTransferFunction controller;
  // Open loop, band-limited input (not held): the input over [t_k, t_k+1) is
  // the straight line from u_k to u_k+1 (first-order hold), taken at the middle
  // of each substep. With one substep that is the held value (u_k + u_k+1) / 2.
  bool interpolate_input = false;
  // Integration substeps per sample: the nonlinear branches are re-evaluated
  // every T / substeps (a cubic term makes harmonics near Nyquist when
  // w T ~ 0.7, as on the Silverbox). 1 is the simulator's structure.
  int substeps = 1;
  // The input between samples as the simulation takes it (interpolated only in
  // open loop), for the fits that start it.
  Hold input_hold() const { return interpolate_input && !closed ? Hold::foh : Hold::zoh; }
  // The additive SRIVC of this loop's linear part (loop, controller, input
  // hold; the cycle of least output error when it does not converge).
  SrivcOptions srivc_options() const;
};

// The model's output on a record (open loop from the measured u, closed loop
// from r and u_ext), and the plant input it used in `u_sim` when given.
Eigen::VectorXd simulate_augmented(const AugmentedModel& model, const Record& data, const LoopSpec& loop,
                                   Eigen::VectorXd* u_sim = nullptr);

// One residual test: its statistic against a threshold.
struct ResidualTest {
  std::string name;
  double statistic = 0.0;
  double threshold = 0.0;
  bool pass = false;
};

struct ResidualAnalysis {
  // Autocorrelation of e at lags 1..M against the 99 % band 2.58/sqrt(N):
  // statistic = the largest |rho|, pass when at most 5 % of the lags are outside
  // and none is outside twice the band.
  ResidualTest whiteness;
  // Cross-correlation of e with past input u(k - tau), tau = 0..M, same band and rule.
  ResidualTest independence;
  // Largest residual-input coherence against its 99 % level for zero coherence
  // with K averaged segments, 1 - 0.01^(1/(K-1)).
  ResidualTest coherence;
  Eigen::VectorXd autocorrelation;    // lags 0..M
  Eigen::VectorXd cross_correlation;  // lags 0..M
  Spectra spectra;
  bool pass() const { return whiteness.pass && independence.pass; }
};
ResidualAnalysis analyse_residual(const Eigen::VectorXd& e, const Eigen::VectorXd& u, double T, int max_lag);

// One fit of a run, for a caller that shows progress: the configured structure
// (step 0, effect "none"), the current model refitted alone (effect "refit") or
// a candidate tried at step >= 1.
struct DiagnoseProgress {
  int step = 0;
  std::string effect;
  double validation_rms = 0.0;
  bool valid = true;  // false when the fit failed (note says why)
  std::string note;
};

struct DiagnoseOptions {
  int max_steps = 5;  // effects added at most
  // An effect is added when its credit is more than this fraction of the
  // validation RMS of the refit without it.
  double min_improvement = 0.10;
  int max_delay = 10;       // samples
  int max_lag = 25;         // residual correlation lags
  int oe_iterations = 40;   // Levenberg-Marquardt iterations of the output-error refinement
  int max_modes_added = 4;  // modes added at most (the mode candidate is not tried past it)
  // Samples at the start of the validation record that only set the model's
  // state (the estimation part before a split): simulated, not scored.
  Eigen::Index validation_lead_in = 0;
  Hold output_hold = Hold::zoh;  // SRIVC prefilters
  std::vector<EffectKind> library = all_effects();
  std::function<void(const DiagnoseProgress&)> progress;  // called after each fit when set
};

using EffectParams = std::vector<std::pair<std::string, double>>;

struct Candidate {
  EffectKind kind = EffectKind::mode;
  EffectParams params;
  AugmentedModel model;
  double estimation_rms = 0.0;
  double validation_rms = 0.0;
  double fit_percent = 0.0;  // validation
  double bic = 0.0;          // N ln(MSE_est) + k ln N on the estimation part
  // What the effect itself lowers the validation RMS by: the refit of the
  // model without it (DiagnoseStep::refit) minus validation_rms. NaN when not valid.
  double credit = std::numeric_limits<double>::quiet_NaN();
  bool valid = true;  // false when the fit failed (note says why)
  std::string note;
};

// The current model refitted alone, from the same start and with the same
// iterations as each candidate's fit: a candidate that only continues the
// refinement gains nothing over it.
struct Refit {
  AugmentedModel model;
  double estimation_rms = std::numeric_limits<double>::infinity();
  double validation_rms = std::numeric_limits<double>::infinity();
  double fit_percent = -std::numeric_limits<double>::infinity();
  double bic = std::numeric_limits<double>::infinity();
  bool valid = false;  // its simulation is finite on the validation part
};

struct DiagnoseStep {
  // effect_name of the added effect; "refit" for a last step that adds none:
  // the model before it refitted alone, taken when that earns what an effect
  // must (its refit_validation_rms is then that model's validation RMS).
  std::string effect = "none";
  EffectParams params;
  AugmentedModel model;
  double estimation_rms = 0.0;
  double validation_rms = 0.0;
  double fit_percent = 0.0;
  double bic = 0.0;
  ResidualAnalysis residual;          // on the validation part
  Eigen::VectorXd validation_output;  // simulated
  std::vector<Candidate> ranking;     // candidates tried from this step, best first (by credit)
  Refit refit;                        // of this step's model, when candidates were tried from it
  // Steps >= 1: the validation RMS of the previous step's refit (the model
  // without the added effect) and the added effect's credit over it. NaN at step 0.
  double refit_validation_rms = std::numeric_limits<double>::quiet_NaN();
  double credit = std::numeric_limits<double>::quiet_NaN();
  // Verdicts of the physical check (physical.hpp) on this step's fit, other
  // than physical: the model above is the corrected one.
  std::vector<ModeFinding> physical;
  // Standard deviations of (wn, zeta, gain) of each submodel of model.linear,
  // first order from the output-error covariance on the estimation part
  // (zeros when unknown): what tells two close modes apart.
  std::vector<ModalParameters> modal_std;
};

// The rule that ended the augmentation.
enum class DiagnoseStop {
  residual_passes,  // whiteness and independence pass: nothing left to explain
  diverges,         // the model's simulation is not finite on the validation part
  max_steps,        // options.max_steps effects added
  min_improvement,  // the best candidate's credit is less than options.min_improvement of the refit's validation RMS
  bic,              // the best candidate does not lower the BIC of the refit without it
  mode_cap,         // options.max_modes_added modes added, and no other effect qualifies
  not_fitted,       // no candidate could be fitted, or none the rules admit simulates once made physical
                    // (stop_reason names each and why)
};
const char* stop_name(DiagnoseStop stop);

struct DiagnoseResult {
  std::vector<DiagnoseStep> steps;  // steps[0]: the configured structure
  DiagnoseStop stop = DiagnoseStop::max_steps;
  std::string stop_reason;  // the rule and the numbers that decided it
};

// Throws std::invalid_argument for records too short or a closed loop without r.
DiagnoseResult diagnose(const Record& estimation, const Record& validation, const AdditiveModel& initial,
                        const LoopSpec& loop, const DiagnoseOptions& options);

}  // namespace modalwatch
