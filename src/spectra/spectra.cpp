// Welch spectra of two signals (Hann window, 50 % overlap) on a radix-2 FFT.
#include <algorithm>
#include <cmath>
#include <complex>
#include <numbers>
#include <stdexcept>
#include <vector>

#include "modalwatch/spectra.hpp"

namespace modalwatch {
namespace {

using Complex = std::complex<double>;

// In-place radix-2 FFT; x.size() is a power of two.
void fft(std::vector<Complex>& x) {
  const std::size_t n = x.size();
  for (std::size_t i = 1, j = 0; i < n; ++i) {
    std::size_t bit = n >> 1;
    for (; j & bit; bit >>= 1) j ^= bit;
    j ^= bit;
    if (i < j) std::swap(x[i], x[j]);
  }
  for (std::size_t len = 2; len <= n; len <<= 1) {
    const double angle = -2.0 * std::numbers::pi / static_cast<double>(len);
    const Complex wlen(std::cos(angle), std::sin(angle));
    for (std::size_t i = 0; i < n; i += len) {
      Complex w(1.0, 0.0);
      for (std::size_t j = 0; j < len / 2; ++j) {
        const Complex a = x[i + j], b = x[i + j + len / 2] * w;
        x[i + j] = a + b;
        x[i + j + len / 2] = a - b;
        w *= wlen;
      }
    }
  }
}

}  // namespace

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
  std::vector<Complex> fe(L), fu(L);
  for (int s = 0; s < K; ++s) {
    for (int i = 0; i < L; ++i) {
      fe[i] = Complex((e(s * hop + i) - em) * window(i), 0.0);
      fu[i] = Complex((u(s * hop + i) - um) * window(i), 0.0);
    }
    fft(fe);
    fft(fu);
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
