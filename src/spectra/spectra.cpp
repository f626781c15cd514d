// Welch spectra of two signals (Hann window, 50 % overlap). The FFT is Eigen's
// (its kissfft backend, shipped with Eigen): a real-input half spectrum per
// segment (bench_spectra measures it).
#include <algorithm>
#include <cmath>
#include <complex>
#include <numbers>
#include <stdexcept>
#include <vector>

#include <unsupported/Eigen/FFT>

#include "modalwatch/spectra.hpp"

namespace modalwatch {
using Complex = std::complex<double>;

Spectra welch_spectra(const Eigen::VectorXd& e, const Eigen::VectorXd& u, double T, int segment_length) {
  if (e.size() != u.size()) throw std::invalid_argument("welch_spectra: sizes differ");
  int L = 16;
  while (L * 2 <= segment_length && L * 2 <= e.size()) L *= 2;
  const int hop = L / 2;
  const int K = e.size() >= L ? static_cast<int>((e.size() - L) / hop) + 1 : 0;
  if (K < 1) throw std::invalid_argument("welch_spectra: record shorter than a segment");
  const int F = L / 2 + 1;
  Eigen::VectorXd see = Eigen::VectorXd::Zero(F), suu = Eigen::VectorXd::Zero(F);
  Eigen::VectorXcd seu = Eigen::VectorXcd::Zero(F);
  Eigen::VectorXd window(L);
  for (int i = 0; i < L; ++i) window(i) = 0.5 - 0.5 * std::cos(2.0 * std::numbers::pi * i / L);
  const double wpow = window.squaredNorm();
  const double em = e.mean(), um = u.mean();
  Eigen::FFT<double> fft;
  fft.SetFlag(Eigen::FFT<double>::HalfSpectrum);
  std::vector<double> te(L), tu(L);
  std::vector<Complex> fe, fu;
  for (int s = 0; s < K; ++s) {
    for (int i = 0; i < L; ++i) {
      te[i] = (e(s * hop + i) - em) * window(i);
      tu[i] = (u(s * hop + i) - um) * window(i);
    }
    fft.fwd(fe, te);
    fft.fwd(fu, tu);
    for (int f = 0; f < F; ++f) {
      see(f) += std::norm(fe[f]);
      suu(f) += std::norm(fu[f]);
      seu(f) += fe[f] * std::conj(fu[f]);
    }
  }
  const double scale = T / (wpow * K);  // one-sided densities up to a factor 2, the same for all
  Spectra out;
  out.segments = K;
  out.frequency_hz.resize(F);
  out.residual_psd = see * scale;
  out.input_psd = suu * scale;
  out.residual_to_input.resize(F);
  out.coherence.resize(F);
  out.cross.resize(F);
  const double floor = 1e-300;
  for (int f = 0; f < F; ++f) {
    out.frequency_hz(f) = f / (L * T);
    const Complex h = seu(f) / std::max(suu(f), floor);
    out.cross(f) = h;
    out.residual_to_input(f) = std::abs(h);
    out.coherence(f) = std::norm(seu(f)) / std::max(see(f) * suu(f), floor);
  }
  return out;
}

}  // namespace modalwatch
