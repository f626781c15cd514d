// Initial modes from the data alone: random plants of 1 to 4 modes (fixed
// seeds) fitted by additive SRIVC from the resonances of the frequency
// response estimate, with no configured guess. Every mode must come out within
// 1 % in wn and 20 % in zeta of the truth, in open and in closed loop.
#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdio>
#include <numbers>
#include <random>

#include <gtest/gtest.h>

#include "simulation_support.hpp"

#include "modalwatch/initial_modes.hpp"
#include "modalwatch/physical.hpp"
#include "modalwatch/simulator.hpp"
#include "modalwatch/srivc.hpp"

namespace modalwatch {
namespace {

constexpr double kPi = std::numbers::pi;

// K modes between 2 % and 35 % of the sampling rate, at least 30 % apart in
// frequency, damping 0.01..0.08, gains of either sign with peak heights
// |gain| / (2 zeta) within a factor of 4 of each other.
std::vector<ModalParameters> random_modes(int K, double T, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const double fs = 1.0 / T;
  std::vector<ModalParameters> modes;
  while (static_cast<int>(modes.size()) < K) {
    const double hz = fs * 0.02 * std::pow(0.35 / 0.02, unit(rng));
    const bool apart = std::all_of(modes.begin(), modes.end(), [&](const ModalParameters& m) {
      return std::abs(std::log(m.hz() / hz)) > std::log(1.3);
    });
    if (!apart) continue;
    ModalParameters m;
    m.wn = 2 * kPi * hz;
    m.zeta = 0.01 + 0.07 * unit(rng);
    const double peak = std::pow(4.0, unit(rng));
    m.gain = (unit(rng) < 0.5 ? -1.0 : 1.0) * 2.0 * m.zeta * peak;
    modes.push_back(m);
  }
  std::sort(modes.begin(), modes.end(), [](auto& a, auto& b) { return a.wn < b.wn; });
  return modes;
}

using test_support::plant_of;

ExperimentSpec experiment(double T, double duration, std::uint64_t seed) {
  return test_support::open_loop_prbs(T, duration, seed, 1, 14);
}

// Every true mode matched by a fitted one (both sorted by wn) within the tolerances.
void expect_identified(const std::vector<ModalParameters>& truth, const AdditiveModel& fitted,
                       const std::string& label) {
  std::vector<ModalParameters> got;
  for (const auto& s : fitted.submodels)
    if (s.is_mode()) got.push_back(modal_parameters(s));
  std::sort(got.begin(), got.end(), [](auto& a, auto& b) { return a.wn < b.wn; });
  ASSERT_EQ(got.size(), truth.size()) << label;
  for (std::size_t i = 0; i < truth.size(); ++i) {
    EXPECT_NEAR(got[i].wn, truth[i].wn, 0.01 * truth[i].wn) << label << " mode " << i + 1;
    EXPECT_NEAR(got[i].zeta, truth[i].zeta, 0.2 * truth[i].zeta) << label << " mode " << i + 1;
  }
}

TEST(InitialModes, PeaksOfANoiseFreeResponseAreNearTheModes) {
  const double T = 0.01;
  const std::vector<ModalParameters> truth{{2 * kPi * 5.0, 0.03, 0.06}, {2 * kPi * 18.0, 0.02, -0.04}};
  const auto sim = simulate(plant_of(truth, 200.0), experiment(T, 200.0, 1));
  const std::vector<ModalParameters> peaks = resonance_peaks(frequency_response(sim.record, false), 2);
  ASSERT_EQ(peaks.size(), 2u);
  for (std::size_t i = 0; i < 2; ++i) {
    // The start is rough (Welch resolution 0.1 Hz, Hann leakage): a few per cent.
    EXPECT_NEAR(peaks[i].wn, truth[i].wn, 0.02 * truth[i].wn) << i;
    EXPECT_NEAR(peaks[i].zeta, truth[i].zeta, 0.5 * truth[i].zeta) << i;
    EXPECT_GT(peaks[i].gain * truth[i].gain, 0.0) << i;
    EXPECT_NEAR(peaks[i].gain, truth[i].gain, 0.5 * std::abs(truth[i].gain)) << i;
  }
}

// A held input lags its samples by half a sample, which the estimate removes; a
// band-limited one does not: the two estimates differ by that lag alone.
TEST(InitialModes, TheHoldsHalfSampleLagIsRemovedForAHeldInputOnly) {
  const double T = 0.01;
  const std::vector<ModalParameters> truth{{2 * kPi * 5.0, 0.03, 0.06}};
  const auto sim = simulate(plant_of(truth, 40.0), experiment(T, 40.0, 3));
  const FrequencyResponse held = frequency_response(sim.record, false);
  const FrequencyResponse band_limited = frequency_response(sim.record, false, 0, Hold::foh);
  ASSERT_EQ(held.response.size(), band_limited.response.size());
  for (const double hz : {5.0, 20.0, 40.0}) {
    Eigen::Index k = 0;
    (held.frequency_hz.array() - hz).abs().minCoeff(&k);
    const std::complex<double> lag = band_limited.response(k) / held.response(k);
    EXPECT_NEAR(std::abs(lag), 1.0, 1e-12) << hz;
    EXPECT_NEAR(std::arg(lag), -kPi * held.frequency_hz(k) * T, 1e-12) << hz;
  }
}

// Two modes whose half-power bandwidths (0.019 and 0.034 Hz) are narrower than
// two bins even of 4 averages (0.024 Hz each; the default 8 have 0.049 Hz): the window, not the
// mode, sets the peaks' width there, and leakage lowers the coherence at the
// peaks. The estimate halves its bins while 4 averages remain, and a peak still
// narrower than two bins starts below the bound it gives, zeta < df / f0,
// instead of at a default 10 times the truth; the fit goes on to the truth.
TEST(InitialModes, ModesNarrowerThanTwoBinsGetFinerBinsAndADampingUnderTheirBound) {
  const double T = 0.01;
  const std::vector<ModalParameters> truth{{2 * kPi * 8.0, 0.0012, 0.01}, {2 * kPi * 21.0, 0.0008, -0.006}};
  const auto sim = simulate(plant_of(truth, 30.0), experiment(T, 120.0, 4));
  const FrequencyResponse coarse = frequency_response(sim.record, false);
  const FrequencyResponse h = resolving_response(sim.record, false);
  EXPECT_EQ(coarse.segments, 10);
  EXPECT_EQ(h.segments, 4);
  const double df = h.frequency_hz(1) - h.frequency_hz(0);
  EXPECT_NEAR(df, 0.5 * (coarse.frequency_hz(1) - coarse.frequency_hz(0)), 1e-12);
  const std::vector<ModalParameters> peaks = resonance_peaks(h, 2);
  ASSERT_EQ(peaks.size(), 2u);
  for (std::size_t i = 0; i < 2; ++i) {
    std::printf("peak %zu: %.4f Hz zeta %.5f (truth %.4f Hz, %.5f; bound df / f0 %.5f)\n", i, peaks[i].hz(),
                peaks[i].zeta, truth[i].hz(), truth[i].zeta, df / peaks[i].hz());
    ASSERT_LT(truth[i].zeta, df / truth[i].hz()) << i;
    EXPECT_NEAR(peaks[i].hz(), truth[i].hz(), df) << i;
    EXPECT_LT(peaks[i].zeta, df / peaks[i].hz()) << i;
    EXPECT_GT(peaks[i].zeta, 0.1 * truth[i].zeta) << i;
  }
  std::vector<ModeFinding> findings;
  const FitResult fit = fit_physical(sim.record, initial_modes(h, 2), SrivcOptions{}, findings);
  expect_identified(truth, fit.model, "from the finer bins");
}

// A plant without a resonance: two real poles (zeta 1.5 at 2 Hz). The closest
// non-resonant response to its estimate is a lag of two poles near the
// plant's, and the fit goes on from it to the truth.
TEST(NonResonantStart, ALagOfTwoRealPolesStartsFromALagAndIsFitted) {
  const std::vector<ModalParameters> truth{{2 * kPi * 2.0, 1.5, 2.0}};
  const auto sim = simulate(plant_of(truth, 60.0), experiment(0.01, 100.0, 5));
  const FrequencyResponse h = resolving_response(sim.record, false);
  const NonResonantStart start = non_resonant_start(h);
  ASSERT_EQ(start.structure, "a lag of two poles (zeta >= 0.7)");
  ASSERT_TRUE(start.submodel.is_mode());
  const ModalParameters p = modal_parameters(start.submodel);
  std::printf("start: %.3f Hz zeta %.2f gain %.3f, relative error %.3f\n", p.hz(), p.zeta, p.gain,
              start.relative_error);
  // A start: within a factor of two in frequency and gain.
  EXPECT_GT(p.wn, truth[0].wn / 2.0);
  EXPECT_LT(p.wn, truth[0].wn * 2.0);
  EXPECT_GT(p.gain, truth[0].gain / 2.0);
  EXPECT_LT(p.gain, truth[0].gain * 2.0);
  AdditiveModel model;
  model.submodels = {start.submodel};
  std::vector<ModeFinding> findings;
  const FitResult fit = fit_physical(sim.record, model, SrivcOptions{}, findings);
  ASSERT_EQ(fit.model.submodels.size(), 1u);
  const ModalParameters f = modal_parameters(fit.model.submodels[0]);
  EXPECT_NEAR(f.wn, truth[0].wn, 0.02 * truth[0].wn);
  EXPECT_NEAR(f.zeta, truth[0].zeta, 0.05 * truth[0].zeta);
  EXPECT_NEAR(f.gain, truth[0].gain, 0.02 * truth[0].gain);
}

// A free mass, b0 / p^2, measured as a position and as a velocity: a rigid body
// of the same gain either way (a velocity sensor's response is p times it),
// within the 20 % the Welch estimate of a drifting position allows.
TEST(NonResonantStart, AFreeMassStartsFromARigidBody) {
  for (const int z : {0, 1}) {
    PlantSpec plant;
    PlantMode mass;
    mass.resonant = false;
    mass.submodel = make_rigid_body("mass", 0.5, 2, z);
    plant.modes.push_back(mass);
    plant.noise_variance = 1e-8;
    const auto sim = simulate(plant, experiment(0.01, 100.0, 6));
    const FrequencyResponse h = resolving_response(sim.record, false);
    const NonResonantStart start = non_resonant_start(h, {}, z);
    EXPECT_EQ(start.structure, "a rigid body b0/p^2") << z;
    EXPECT_EQ(start.submodel.rigid_poles, 2) << z;
    EXPECT_EQ(start.submodel.output_derivatives, z);
    EXPECT_NEAR(start.submodel.b(0), 0.5, 0.1) << z;
  }
}

// A static gain under a measured white-noise input (read as foh: a held
// input's half-sample delay is not in y = b0 u): the feedthrough is the
// closest structure by far, with its gain.
TEST(NonResonantStart, AStaticGainStartsFromAFeedthrough) {
  Record r;
  const Eigen::Index n = 10000;
  r.t = Eigen::VectorXd::LinSpaced(n, 0.0, 0.01 * static_cast<double>(n - 1));
  r.u = test_support::white_noise(n, 3);
  r.y = 2.5 * r.u + 0.05 * test_support::white_noise(n, 4);
  const std::vector<NonResonantStart> starts = non_resonant_starts(resolving_response(r, false, Hold::foh));
  ASSERT_FALSE(starts.empty());
  for (const NonResonantStart& s : starts)
    std::printf("%s: relative error %.4f\n", s.structure.c_str(), s.relative_error);
  EXPECT_EQ(starts.front().structure, "a feedthrough b0");
  EXPECT_TRUE(starts.front().submodel.is_feedthrough());
  EXPECT_NEAR(starts.front().submodel.b(0), 2.5, 0.05);
  EXPECT_LT(starts.front().relative_error, 0.05);
}

TEST(InitialModes, FewerPeaksThanAskedWhenTheDataShowFewer) {
  const std::vector<ModalParameters> truth{{2 * kPi * 5.0, 0.03, 0.06}};
  const auto sim = simulate(plant_of(truth, 40.0), experiment(0.01, 100.0, 2));
  const AdditiveModel m = initial_modes(sim.record, 3, false);
  ASSERT_EQ(m.submodels.size(), 1u);
  EXPECT_NEAR(modal_parameters(m.submodels[0]).wn, truth[0].wn, 0.02 * truth[0].wn);
}

// A coloured input (its power 60 dB below its maximum at the resonance, as
// through a steep low-pass) still excites the mode when the output follows it
// closely all the way from the excited band: the coherence puts the resonance
// in the searched band; without it, or with it only around the resonance
// (beyond a band-limited input), the resonance stays outside.
TEST(InitialModes, ACoherentResonanceWhereAColouredInputIsWeakIsSearched) {
  const int F = 257;
  const double wn = 2 * kPi * 0.25, zeta = 0.02, gain = 1.5;  // cycles/sample: T = 1
  FrequencyResponse h;
  h.frequency_hz = Eigen::VectorXd::LinSpaced(F, 0.0, 0.5);
  h.response.resize(F);
  h.excitation.resize(F);
  h.coherence.resize(F);
  h.segments = 10;
  for (int k = 0; k < F; ++k) {
    const double x = 2 * kPi * h.frequency_hz(k) / wn;
    h.response(k) = gain / std::complex<double>(1.0 - x * x, 2.0 * zeta * x);
    h.excitation(k) = std::pow(10.0, -6.0 * h.frequency_hz(k) / 0.25);  // -60 dB at the mode
    h.coherence(k) = 0.95;
  }
  const std::vector<ModalParameters> peaks = resonance_peaks(h, 1);
  ASSERT_EQ(peaks.size(), 1u);
  EXPECT_NEAR(peaks[0].wn, wn, 0.01 * wn);
  EXPECT_NEAR(peaks[0].zeta, zeta, 0.5 * zeta);
  h.coherence.setConstant(0.1);
  EXPECT_TRUE(resonance_peaks(h, 1).empty());
  // Coherent around the peak only, apart from the excited band: not searched.
  for (int k = 0; k < F; ++k) h.coherence(k) = std::abs(h.frequency_hz(k) - 0.25) < 0.03 ? 0.95 : 0.1;
  EXPECT_TRUE(resonance_peaks(h, 1).empty());
}

TEST(InitialModes, RandomPlantsIdentifiedWithoutAStartingGuessInOpenLoop) {
  const double T = 0.01;
  for (std::uint64_t seed = 1; seed <= 8; ++seed) {
    std::mt19937_64 rng(seed);
    const int K = 1 + static_cast<int>((seed - 1) % 4);
    const std::vector<ModalParameters> truth = random_modes(K, T, rng);
    const auto sim = simulate(plant_of(truth, 30.0), experiment(T, 120.0, seed));
    const AdditiveModel start = initial_modes(sim.record, K, false);
    ASSERT_EQ(static_cast<int>(start.submodels.size()), K) << "seed " << seed;
    std::vector<ModeFinding> findings;
    const FitResult fit = fit_physical(sim.record, start, SrivcOptions{}, findings);
    expect_identified(truth, fit.model, "seed " + std::to_string(seed));
  }
}

// A proportional controller at half the gain that would close the loop at the
// largest peak: stable for any such plant (small gain), and active at its modes.
DiscreteTransferFunction controller_for(const PlantSpec& plant, double T) {
  const AdditiveModel m = plant_model_at(plant, 0.0);
  double largest = 0.0;
  for (double w = 0.0; w < kPi / T; w += 0.01) largest = std::max(largest, std::abs(m.response(w)));
  return DiscreteTransferFunction({0.5 / largest}, {1.0});
}

// Closed loop: the start from S_yr / S_ur (the default with r in the record),
// and from the biased H1 = S_yu / S_uu; the closed-loop instruments take both
// to the truth.
TEST(InitialModes, RandomPlantsIdentifiedWithoutAStartingGuessInClosedLoop) {
  const double T = 0.01;
  for (std::uint64_t seed = 1; seed <= 8; ++seed) {
    std::mt19937_64 rng(seed);
    const int K = 1 + static_cast<int>((seed - 1) % 4);
    const std::vector<ModalParameters> truth = random_modes(K, T, rng);
    const PlantSpec plant = plant_of(truth, 30.0);
    ExperimentSpec e = experiment(T, 120.0, seed);
    e.closed_loop = true;
    e.controller = controller_for(plant, T);
    const auto sim = simulate(plant, e);
    SrivcOptions options;
    options.closed_loop = true;
    options.controller = e.controller;
    for (const bool h1 : {false, true}) {
      const std::string label = "seed " + std::to_string(seed) + (h1 ? " from H1" : " from S_yr/S_ur");
      const AdditiveModel start = initial_modes(sim.record, K, !h1);
      ASSERT_EQ(static_cast<int>(start.submodels.size()), K) << label;
      std::vector<ModeFinding> findings;
      const FitResult fit = fit_physical(sim.record, start, options, findings);
      expect_identified(truth, fit.model, label);
    }
  }
}

}  // namespace
}  // namespace modalwatch
