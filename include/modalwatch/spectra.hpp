#pragma once
// Welch estimates of two signals e and u (Hann window, 50 % overlap, means
// removed): their densities, the ratio S_eu / S_uu and the coherence. The
// residual analysis of `diagnose` reads e as the residual; the start of a fit
// from the data (initial_modes.hpp) reads it as the output, S_eu / S_uu then
// being the frequency response estimate H1.
#include <Eigen/Core>

namespace modalwatch {

struct Spectra {
  Eigen::VectorXd frequency_hz;
  Eigen::VectorXd residual_psd;
  Eigen::VectorXd input_psd;
  Eigen::VectorXd residual_to_input;  // |S_eu / S_uu|
  Eigen::VectorXd coherence;          // |S_eu|^2 / (S_ee S_uu)
  int segments = 0;
  Eigen::VectorXcd cross;  // S_eu / S_uu (complex), for mode starts
};
Spectra welch_spectra(const Eigen::VectorXd& e, const Eigen::VectorXd& u, double T, int segment_length);

}  // namespace modalwatch
