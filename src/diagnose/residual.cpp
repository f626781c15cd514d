// Residual tests: whiteness (autocorrelation), independence from past input
// (cross-correlation), Welch spectra and residual-input coherence.
#include <algorithm>
#include <cmath>
#include <complex>
#include <numbers>
#include <stdexcept>

#include "modalwatch/diagnose.hpp"

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

// Correlation of a and b at lag tau (b delayed): sum a(k) b(k - tau) / N,
// normalised by the standard deviations.
double correlation(const Eigen::VectorXd& a, const Eigen::VectorXd& b, int tau, double norm) {
  const Eigen::Index N = a.size();
  double s = 0.0;
  for (Eigen::Index k = tau; k < N; ++k) s += a(k) * b(k - tau);
  return s / static_cast<double>(N) / norm;
}

// Pass when at most 5 % of the lags are outside the band (chance exceedances
// at 1 % per lag) and none is outside twice the band (for a white residual a
// 5.2 sigma event: one strongly correlated lag is a failure).
ResidualTest band_test(const std::string& name, const Eigen::VectorXd& rho, double band) {
  ResidualTest t;
  t.name = name;
  t.threshold = band;
  int outside = 0;
  for (Eigen::Index i = 0; i < rho.size(); ++i) {
    t.statistic = std::max(t.statistic, std::abs(rho(i)));
    if (std::abs(rho(i)) > band) ++outside;
  }
  t.pass = outside <= static_cast<int>(std::floor(0.05 * static_cast<double>(rho.size()))) && t.statistic <= 2.0 * band;
  return t;
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

ResidualAnalysis analyse_residual(const Eigen::VectorXd& e, const Eigen::VectorXd& u, double T, int max_lag) {
  const Eigen::Index N = e.size();
  if (N < 4 * max_lag || u.size() != N) throw std::invalid_argument("analyse_residual: record too short");
  const Eigen::VectorXd ec = e.array() - e.mean();
  const Eigen::VectorXd uc = u.array() - u.mean();
  const double se = std::sqrt(ec.squaredNorm() / N), su = std::sqrt(uc.squaredNorm() / N);
  ResidualAnalysis a;
  a.autocorrelation.resize(max_lag + 1);
  a.cross_correlation.resize(max_lag + 1);
  for (int tau = 0; tau <= max_lag; ++tau) {
    a.autocorrelation(tau) = se > 0 ? correlation(ec, ec, tau, se * se) : 0.0;
    a.cross_correlation(tau) = (se > 0 && su > 0) ? correlation(ec, uc, tau, se * su) : 0.0;
  }
  const double band = 2.58 / std::sqrt(static_cast<double>(N));  // 99 % for a white residual
  a.whiteness = band_test("whiteness", a.autocorrelation.tail(max_lag), band);
  a.independence = band_test("independence", a.cross_correlation, band);
  const int segment = static_cast<int>(std::min<Eigen::Index>(1024, std::max<Eigen::Index>(64, N / 8)));
  a.spectra = welch_spectra(e, u, T, segment);
  const int K = a.spectra.segments;
  a.coherence.name = "coherence";
  // 99 % level of the largest squared-coherence estimate of uncorrelated
  // signals over the M excited frequencies (Bonferroni), K averages (ignoring
  // the overlap): 1 - (0.01/M)^(1/(K-1)).
  const Eigen::VectorXd& psd = a.spectra.input_psd;
  const double excited = 1e-3 * psd.maxCoeff();
  int M = 0;
  for (Eigen::Index f = 1; f < psd.size(); ++f)
    if (psd(f) > excited) {
      ++M;
      a.coherence.statistic = std::max(a.coherence.statistic, a.spectra.coherence(f));
    }
  a.coherence.threshold = (K > 1 && M > 0) ? 1.0 - std::pow(0.01 / M, 1.0 / (K - 1)) : 1.0;
  a.coherence.pass = a.coherence.statistic <= a.coherence.threshold;
  return a;
}

}  // namespace modalwatch
