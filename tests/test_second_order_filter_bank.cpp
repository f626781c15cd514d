// The recursive estimator's mode prefilters (SecondOrderFilterBank, private to
// the estimator): four held signals through one shared, per-sample
// re-discretised 1/A(p), against one Prefilter per signal.
#include <algorithm>
#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "estimator/second_order_filter_bank.hpp"
#include "modalwatch/model.hpp"
#include "modalwatch/prefilter.hpp"

namespace modalwatch {
namespace {

using detail::SecondOrderFilterBank;

// D = A(p) of a mode: 1 + (2 zeta / wn) p + p^2 / wn^2.
Eigen::VectorXd mode_denominator(double wn, double zeta) {
  const Submodel mode = make_mode("mode", {wn, zeta, 1.0});
  Eigen::VectorXd d(3);
  d << 1.0, mode.a(0), mode.a(1);
  return d;
}

TEST(SecondOrderFilterBank, MatchesOnePrefilterPerSignalWhileTheDenominatorChanges) {
  // The recursive estimator's mode prefilters: one shared discretisation,
  // re-discretised every sample, against four Prefilters given the same
  // denominators. wn T sweeps 0.025..1.25 (series and closed-form branches).
  const double T = 0.05;
  const int n = 3000;
  auto denominator = [&](int k) { return mode_denominator(0.5 + 24.5 * k / n, 0.02 + 0.3 * k / n); };
  std::vector<Prefilter> reference;
  for (int i = 0; i < SecondOrderFilterBank::kSignals; ++i) reference.emplace_back(denominator(0), T, Hold::zoh);
  SecondOrderFilterBank bank;
  double worst = 0.0;
  for (int k = 0; k < n; ++k) {
    const Eigen::VectorXd d = denominator(k);
    bank.set_denominator(d(0), d(1), d(2), T);
    for (auto& f : reference) f.set_denominator(d);
    for (int i = 0; i < SecondOrderFilterBank::kSignals; ++i) {
      const double w = std::sin(0.37 * k * (i + 1)) + 0.2 * i;
      const double* got;
      if (i == 3) {  // two-phase, as the closed-loop instrument input
        bank.advance(i);
        reference[i].advance();
        bank.complete(i, 0.0);
        reference[i].complete(0.0);
        got = bank.complete(i, w);
        reference[i].complete(w);
      } else {
        got = bank.step(i, w);
        reference[i].step(w);
      }
      const FilterVector& want = reference[i].derivatives();
      ASSERT_EQ(got, bank.derivatives(i));
      for (int j = 0; j <= 2; ++j) {
        const double scale = 1.0 + std::abs(want(j));
        ASSERT_NEAR(got[j], want(j), 1e-12 * scale) << "k=" << k << " signal " << i << " derivative " << j;
        worst = std::max(worst, std::abs(got[j] - want(j)) / scale);
      }
    }
  }
  EXPECT_LT(worst, 1e-12);
  bank.reset();
  for (int i = 0; i < SecondOrderFilterBank::kSignals; ++i)
    for (int j = 0; j <= 2; ++j) EXPECT_EQ(bank.derivatives(i)[j], 0.0);
}

TEST(SecondOrderFilterBank, AdvancingAllSignalsAtOnceMatchesOnePrefilterPerSignal) {
  // The estimator's order of work: advance_all() moves the four held-input
  // states to t_k, then complete() takes each sample. Against four Prefilters
  // stepped one by one, with the denominator changing every sample across the
  // series and closed-form branches (wn T = 0.025..2.5).
  const double T = 0.05;
  const int n = 3000;
  auto denominator = [&](int k) { return mode_denominator(0.5 + 49.5 * k / n, 0.02 + 0.5 * k / n); };
  std::vector<Prefilter> reference;
  for (int i = 0; i < SecondOrderFilterBank::kSignals; ++i) reference.emplace_back(denominator(0), T, Hold::zoh);
  SecondOrderFilterBank bank;
  const Eigen::VectorXd d_start = denominator(0);
  bank.set_denominator(d_start(0), d_start(1), d_start(2), T);
  double worst = 0.0;
  for (int k = 0; k < n; ++k) {
    bank.advance_all();
    for (int i = 0; i < SecondOrderFilterBank::kSignals; ++i) {
      const double w = std::cos(0.23 * k * (i + 1)) - 0.1 * i;
      const double* got = bank.complete(i, w);
      const FilterVector& want = reference[i].step(w);
      for (int j = 0; j <= 2; ++j) {
        const double scale = 1.0 + std::abs(want(j));
        ASSERT_NEAR(got[j], want(j), 1e-12 * scale) << "k=" << k << " signal " << i << " derivative " << j;
        worst = std::max(worst, std::abs(got[j] - want(j)) / scale);
      }
    }
    const Eigen::VectorXd d = denominator(k + 1);
    bank.set_denominator(d(0), d(1), d(2), T);
    for (auto& f : reference) f.set_denominator(d);
  }
  EXPECT_LT(worst, 1e-12);
}

TEST(SecondOrderFilterBank, CompleteStateGivesTheStateAndKeepsTheFilterOnTrack) {
  // The estimator's u and z of a mode (B = b0) need [w_f, p w_f] only:
  // complete_state() leaves p^2 w_f out but must hold the input as complete()
  // does, so that the state at the next sample is the same. Signals 0 and 1 take
  // complete(), 2 and 3 complete_state(), all against one Prefilter each, with
  // the discretisation handed in (the estimator's set_denominator overload).
  const double T = 0.05;
  const int n = 2000;
  auto denominator = [&](int k) { return mode_denominator(0.5 + 24.5 * k / n, 0.02 + 0.3 * k / n); };
  std::vector<Prefilter> reference;
  for (int i = 0; i < SecondOrderFilterBank::kSignals; ++i) reference.emplace_back(denominator(0), T, Hold::zoh);
  SecondOrderFilterBank bank;
  const Eigen::VectorXd d_start = denominator(0);
  bank.set_denominator(d_start(0), d_start(1), d_start(2),
                       discretize_second_order(d_start(0), d_start(1), d_start(2), T));
  double worst = 0.0;
  for (int k = 0; k < n; ++k) {
    bank.advance_all();
    for (int i = 0; i < SecondOrderFilterBank::kSignals; ++i) {
      const double w = std::sin(0.31 * k * (i + 1)) + 0.3 * i;
      const double* got = i < 2 ? bank.complete(i, w) : bank.complete_state(i, w);
      const FilterVector& want = reference[i].step(w);
      for (int j = 0; j <= (i < 2 ? 2 : 1); ++j) {
        const double scale = 1.0 + std::abs(want(j));
        ASSERT_NEAR(got[j], want(j), 1e-12 * scale) << "k=" << k << " signal " << i << " derivative " << j;
        worst = std::max(worst, std::abs(got[j] - want(j)) / scale);
      }
    }
    const Eigen::VectorXd d = denominator(k + 1);
    bank.set_denominator(d(0), d(1), d(2), discretize_second_order(d(0), d(1), d(2), T));
    for (auto& f : reference) f.set_denominator(d);
  }
  EXPECT_LT(worst, 1e-12);
}

}  // namespace
}  // namespace modalwatch
