#pragma once
// Initial modes from the data alone: the additive fit (srivc.hpp) starts from
// the resonances of a nonparametric frequency response estimate instead of
// configured guesses.
//
// The estimate is H1 = S_yu / S_uu (Welch: Hann windows, 50 % overlap) in open
// loop; with several measured inputs (Record::further_u) the row H = S_yu S_uu^-1
// of one response per input, from the inputs' cross-spectral matrix S_uu at
// each frequency (correlated inputs are separated), and the resonances are the
// peaks of |H| = sqrt(sum_j |H_j|^2): a mode that one input hardly excites
// still shows through the other. In closed loop H1 is biased by the noise fed back into u; with the
// reference in the record the estimate is S_yr / S_ur, which the noise does
// not reach (the fit's instruments correct what remains). The resonances are
// the local maxima of |H| over the excited band that rise most above their
// surroundings (in |H|, not in dB: ripples where |H| is small rank low): damping from
// the half-power bandwidth (default_zeta when it is not resolved, and at most
// half the bound df / f0 when it is under two bins df), gain
// from the peak, b0 = -2 zeta Im H(j wn) for b0 / (p^2/wn^2 + 2 zeta/wn p + 1).
// A velocity or acceleration sensor (z = 1, 2) peaks at the same wn, but its
// response is (j w)^z times the position's: the gain is read from H / (j wn)^z.
#include <array>
#include <complex>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "modalwatch/model.hpp"
#include "modalwatch/prefilter.hpp"
#include "modalwatch/record.hpp"

namespace modalwatch {

struct FrequencyResponse {
  Eigen::VectorXd frequency_hz;
  Eigen::VectorXcd response;   // H(j 2 pi f), with the half-sample delay of a held input removed
  Eigen::VectorXd excitation;  // power of the excitation (u in open loop, r in closed loop) per frequency
  Eigen::VectorXd coherence;   // squared coherence of y with the excitation (multiple coherence: several inputs)
  int segments = 0;
  // Several inputs: H_2, H_3, ... of the inputs after the first (response is
  // H_1); the excitation is then the inputs' summed power. Empty for one input.
  std::vector<Eigen::VectorXcd> further_responses;

  int inputs() const { return 1 + static_cast<int>(further_responses.size()); }
  const Eigen::VectorXcd& input_response(int j) const {
    return j == 0 ? response : further_responses[static_cast<std::size_t>(j - 1)];
  }
  // |H| at bin k: |H_1|, or sqrt(sum_j |H_j|^2) with several inputs.
  double magnitude(Eigen::Index k) const;
};

// segment_length 0: the longest power of two that still gives 8 averaged
// segments. A held input (Hold::zoh) lags the samples by half a sample, which
// is removed; a band-limited input (Hold::foh, interpolated between samples)
// does not. Several inputs in closed loop throw std::invalid_argument (the
// controller gives one u).
FrequencyResponse frequency_response(const Record& data, bool closed_loop, int segment_length = 0,
                                     Hold input = Hold::zoh);

// The estimate that resonances are read from (the starts of `fit` and
// `diagnose`): frequency_response's, its segments doubled while a resonance
// peak is narrower than two bins, at least 4 segments remain and the finer
// estimate shows as many peaks. A lightly damped mode's leakage lowers the
// coherence at its peak, which the peak test reads as noise.
FrequencyResponse resolving_response(const Record& data, bool closed_loop, Hold input = Hold::zoh);

struct PeakOptions {
  double default_zeta = 0.02;  // when the half-power bandwidth is not resolved
  // The searched band runs from the first to the last frequency with at least
  // this share of the largest excitation power, widened on each side over the
  // adjacent frequencies whose squared coherence is at least `coherent`, up to
  // the first that falls below it: a coloured input that rolls off can lie
  // decades below its maximum where the output still follows it closely, while
  // coherence in scattered bins beyond a band-limited input is no excitation.
  double excited_fraction = 1e-3;
  double coherent = 0.5;
  // A peak must rise above the higher of its two flanking minima by this many
  // relative standard deviations of |H| (from the coherence and the number of
  // segments), by min_prominence of its height at least, and by min_share of
  // the largest peak's rise.
  double noise_sigmas = 3.0;
  double min_prominence = 0.05;
  double min_share = 0.01;
};

// The DC gain b0 of a mode at wn, zeta whose measured response at its peak is
// h = (j wn)^z b0 / (j 2 zeta): -2 zeta Im(h / (j wn)^z), or 2 zeta |h| / wn^z
// when that is zero.
double resonance_gain(std::complex<double> h, double wn, double zeta, int output_derivatives = 0);

// The `count` most prominent resonances of H (fewer when the data show fewer),
// ascending in wn; the gains of a sensor measuring the z-th derivative.
std::vector<ModalParameters> resonance_peaks(const FrequencyResponse& h, int count, const PeakOptions& options = {},
                                             int output_derivatives = 0);

// The additive model of those resonances, named mode1..modeN in ascending
// frequency. With several inputs each resonance is one submodel per input, of
// the same wn and zeta and that input's residue, named mode<k>_<input> after
// `inputs` (the model's input names; u1, u2, ... when not given). The modes
// measure the z-th derivative of their position (Submodel::output_derivatives).
AdditiveModel initial_modes(const FrequencyResponse& h, int count, const PeakOptions& options = {},
                            const std::vector<std::string>& inputs = {}, int output_derivatives = 0);
// A record whose response shows no resonance peak (a lag, a stage under
// position feedback, a step on a rigid body) still has a start: the one of a
// feedthrough b0 (position sensor only), a rigid body b0/p or b0/p^2, a lag of
// one pole measured as b0 / (1 + p/wc) (b0 / (p^z (1 + p/wc)) in position, z
// the output's derivatives: a motor's speed is a lag), a rigid body behind a
// lag b0 / (p (1 + p/wc)) (a positioning axis with viscous friction), or a lag of two poles
// b0 / (p^2/wn^2 + 2 zeta/wn p + 1) with zeta >= 0.7, wc and wn on a grid
// over the band, whose response (b0 fitted) is closest to H over the
// excited band in relative terms and per decade, sum gamma^2 |H - G|^2 / (|H|^2 f)
// with the squared coherence gamma^2 discounting the bins noise makes. One input only: with
// several, or a band of fewer than three bins, `structure` is empty.
struct NonResonantStart {
  Submodel submodel;
  std::string structure;                // which of the six, in words; empty: none
  double relative_error = 0.0;          // RMS of |H - G| / |H| over the band, so weighted
  std::array<double, 2> band_hz{0, 0};  // the excited band it was fitted over
};
NonResonantStart non_resonant_start(const FrequencyResponse& h, const PeakOptions& options = {},
                                    int output_derivatives = 0);
// The closest of each structure, closest first (the first is non_resonant_start's);
// empty where non_resonant_start has none.
std::vector<NonResonantStart> non_resonant_starts(const FrequencyResponse& h, const PeakOptions& options = {},
                                                  int output_derivatives = 0);

// The same from a record's resolving_response (held input).
AdditiveModel initial_modes(const Record& data, int count, bool closed_loop, const PeakOptions& options = {},
                            int output_derivatives = 0);

}  // namespace modalwatch
