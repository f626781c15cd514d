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
