// The simulator against analytic truth: continuous-time step responses at the
// sample instants, exact steady-state ZOH sinusoid responses, a time-varying
// mode against an independent per-sample matrix-exponential reference, the
// closed-loop law u = C(r - y) sample by sample, noise statistics, and the
// shipped configurations (stable loops with margins, and a short run each).
#include <cmath>
#include <complex>
#include <filesystem>
#include <numbers>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <unsupported/Eigen/MatrixFunctions>

#include "support.hpp"

#include "modalwatch/io/config.hpp"
#include "modalwatch/simulator.hpp"

namespace modalwatch {
namespace {

constexpr double kPi = std::numbers::pi;

PlantMode resonant(const std::string& name, double wn, double zeta, double gain) {
  PlantMode m;
  m.modal = {wn, zeta, gain};
  m.submodel = make_mode(name, m.modal);
  m.resonant = true;
  return m;
}

PlantMode fixed(const Submodel& s) {
  PlantMode m;
  m.submodel = s;
  m.resonant = false;
  return m;
}

// (b_0 + ... + b_m p^m) / (p^l (1 + a_1 p + ... + a_n p^n)).
Submodel transfer_function(const std::string& name, std::vector<double> a, std::vector<double> b, int l) {
  Submodel s;
  s.name = name;
  s.n = static_cast<int>(a.size());
  s.m = static_cast<int>(b.size()) - 1;
  s.rigid_poles = l;
  s.a = Eigen::Map<Eigen::VectorXd>(a.data(), s.n);
  s.b = Eigen::Map<Eigen::VectorXd>(b.data(), s.m + 1);
  return s;
}

ExperimentSpec open_loop(double T, const Eigen::VectorXd& u) {
  ExperimentSpec e;
  e.sample_time = T;
  e.duration = T * static_cast<double>(u.size());
  e.excitation_samples = u;
  return e;
}

Eigen::VectorXd times(Eigen::Index n, double T) {
  return Eigen::VectorXd::LinSpaced(n, 0.0, static_cast<double>(n - 1)) * T;
}

DiscreteTransferFunction paper_controller() { return {{0.02329, -0.02058, 0.00454}, {1.0, -1.0, 0.0}}; }

PlantSpec paper_plant() {
  PlantSpec p;
  p.modes = {resonant("mode1", 2.0, 0.25, 3.0), resonant("mode2", 5.0, 0.025, 0.5), resonant("mode3", 20.0, 0.1, 1.0)};
  return p;
}

SignalSpec paper_reference() {
  SignalSpec r;
  r.kind = SignalSpec::Kind::sum_of_sines;
  r.amplitudes = {3.0, 1.0, 1.0, 1.0};
  r.frequencies_rad_s = {0.005, 2.0, 5.0, 17.5};
  return r;
}

ExperimentSpec closed_loop(double T, double duration, const DiscreteTransferFunction& c, const SignalSpec& r) {
  ExperimentSpec e;
  e.sample_time = T;
  e.duration = duration;
  e.closed_loop = true;
  e.controller = c;
  e.excitation = r;
  return e;
}

// ---------------------------------------------------------------- reference ZOH model

// The plant as x+ = phi x + gamma u, y = c x + d u: per submodel the
// controllable canonical form of B/(p^l A), discretised by the matrix
// exponential of [[A, B], [0, 0]] T (independent of the Prefilter's closed forms).
struct ZohPlant {
  Eigen::MatrixXd phi;
  Eigen::VectorXd gamma;
  Eigen::RowVectorXd c;
  double d = 0.0;
};

ZohPlant zoh_plant(const AdditiveModel& model, double T) {
  int n = 0;
  for (const Submodel& s : model.submodels) n += s.n + s.rigid_poles;
  Eigen::MatrixXd M = Eigen::MatrixXd::Zero(n + 1, n + 1);
  ZohPlant z;
  z.c = Eigen::RowVectorXd::Zero(n);
  int o = 0;
  for (const Submodel& s : model.submodels) {
    const Eigen::VectorXd d = s.denominator();
    const int N = static_cast<int>(d.size()) - 1;
    const double bN = s.m == N ? s.b(N) : 0.0;
    for (int j = 0; j + 1 < N; ++j) M(o + j, o + j + 1) = 1.0;
    for (int j = 0; j < N; ++j) {
      M(o + N - 1, o + j) = -d(j) / d(N);
      z.c(o + j) = (j <= s.m ? s.b(j) : 0.0) - bN * d(j) / d(N);
    }
    if (N > 0) M(o + N - 1, n) = 1.0 / d(N);
    z.d += bN / d(N);
    o += N;
  }
  const Eigen::MatrixXd E = (M * T).exp();
  z.phi = E.topLeftCorner(n, n);
  z.gamma = E.topRightCorner(n, 1);
  return z;
}

std::complex<double> zoh_response(const ZohPlant& g, double w, double T) {
  using cd = std::complex<double>;
  const Eigen::Index n = g.phi.rows();
  const Eigen::MatrixXcd A = std::polar(1.0, w * T) * Eigen::MatrixXcd::Identity(n, n) - g.phi.cast<cd>();
  const Eigen::VectorXcd x = A.partialPivLu().solve(g.gamma.cast<cd>());
  return (g.c.cast<cd>() * x)(0) + g.d;
}

double spectral_radius(const DiscreteTransferFunction& c, const ZohPlant& g) {
  return closed_loop_spectral_radius(c, g.phi, g.gamma, g.c, g.d);
}

// Loop robustness from L = C G on a log grid up to Nyquist.
struct Margins {
  double min_return = 1e300;        // min |1 + L| (1 / peak sensitivity)
  double min_phase_margin = 1e300;  // deg, over all gain crossovers
};

Margins margins(const DiscreteTransferFunction& c, const ZohPlant& g, double T) {
  Margins m;
  const int points = 20000;
  const double w0 = 0.5, w1 = 0.999 * kPi / T;
  double previous = -1.0;
  for (int i = 0; i < points; ++i) {
    const double w = w0 * std::pow(w1 / w0, static_cast<double>(i) / (points - 1));
    const std::complex<double> L = c.response(w, T) * zoh_response(g, w, T);
    m.min_return = std::min(m.min_return, std::abs(1.0 + L));
    const double mag = std::abs(L);
    if (previous > 0.0 && (previous - 1.0) * (mag - 1.0) <= 0.0)
      m.min_phase_margin = std::min(m.min_phase_margin, 180.0 - std::abs(std::arg(L)) * 180.0 / kPi);
    previous = mag;
  }
  return m;
}

// ---------------------------------------------------------------- trajectories

TEST(SimulatorTrajectory, PiecewiseLinearHeldOutside) {
  const Trajectory empty;
  EXPECT_EQ(empty.at(3.0, 7.0), 7.0);
  Trajectory tr;
  tr.points = {{100.0, 2.0}, {300.0, 1.6}, {400.0, 1.8}};
  EXPECT_EQ(tr.at(0.0, 9.0), 2.0);
  EXPECT_EQ(tr.at(100.0, 9.0), 2.0);
  EXPECT_NEAR(tr.at(200.0, 9.0), 1.8, 1e-15);
  EXPECT_NEAR(tr.at(250.0, 9.0), 1.7, 1e-15);
  EXPECT_EQ(tr.at(300.0, 9.0), 1.6);
  EXPECT_NEAR(tr.at(350.0, 9.0), 1.7, 1e-15);
  EXPECT_EQ(tr.at(1e6, 9.0), 1.8);
}

// ---------------------------------------------------------------- open loop, analytic

// Unit step held from t_0: b0 [1 - e^{-sigma t} (cos wd t + sigma/wd sin wd t)].
void expect_mode_step(double wn, double zeta, double gain, double T, Eigen::Index n) {
  PlantSpec plant;
  plant.modes = {resonant("m", wn, zeta, gain)};
  const SimulationResult r = simulate(plant, open_loop(T, Eigen::VectorXd::Ones(n)));
  const double sigma = zeta * wn, wd = wn * std::sqrt(1.0 - zeta * zeta);
  for (Eigen::Index k = 0; k < n; ++k) {
    const double t = static_cast<double>(k) * T;
    const double truth = gain * (1.0 - std::exp(-sigma * t) * (std::cos(wd * t) + sigma / wd * std::sin(wd * t)));
    ASSERT_NEAR(r.y_clean(k), truth, 1e-9 * gain) << "wn=" << wn << " k=" << k;
  }
  EXPECT_EQ(r.record.y, r.y_clean);  // no noise configured
}

TEST(SimulatorOpenLoop, ModeStepResponseIsExactAtSamples) {
  expect_mode_step(20.0, 0.1, 1.0, 0.05, 400);                    // 1 rad per sample (paper's mode 3)
  expect_mode_step(2.0 * kPi * 700.0, 0.01, 2.5e-9, 1e-4, 3000);  // 700 Hz mode at 10 kHz
}

// (b0 + b1 p)/(1 + tau p): step response b0 + (b1/tau - b0) e^{-t/tau}, with
// the feedthrough b1/tau already at t_0.
TEST(SimulatorOpenLoop, BiproperSubmodelStepResponse) {
  const double tau = 0.2, b0 = 2.0, b1 = 0.3, T = 0.01;
  PlantSpec plant;
  plant.modes = {fixed(transfer_function("lead", {tau}, {b0, b1}, 0))};
  const SimulationResult r = simulate(plant, open_loop(T, Eigen::VectorXd::Ones(300)));
  for (Eigen::Index k = 0; k < 300; ++k)
    ASSERT_NEAR(r.y_clean(k), b0 + (b1 / tau - b0) * std::exp(-static_cast<double>(k) * T / tau), 1e-12) << k;
}

// Poles at the origin: 0.5/p^2 gives 0.25 t^2; 3/(p (0.01 p + 1)) gives
// 3 (t - tau + tau e^{-t/tau}) (normalised time ws = 1/tau with l = 1).
TEST(SimulatorOpenLoop, RigidBodyStepResponses) {
  PlantSpec mass;
  mass.modes = {fixed(make_rigid_body("rigid", 0.5, 2))};
  const double T = 1e-3;
  const SimulationResult r = simulate(mass, open_loop(T, Eigen::VectorXd::Ones(2000)));
  for (Eigen::Index k = 0; k < 2000; ++k) {
    const double t = static_cast<double>(k) * T;
    ASSERT_NEAR(r.y_clean(k), 0.25 * t * t, 1e-12 * (1.0 + 0.25 * t * t)) << k;
  }
  const double tau = 0.01;
  PlantSpec lagged;
  lagged.modes = {fixed(transfer_function("rigid_lag", {tau}, {3.0}, 1))};
  const SimulationResult s = simulate(lagged, open_loop(T, Eigen::VectorXd::Ones(500)));
  for (Eigen::Index k = 0; k < 500; ++k) {
    const double t = static_cast<double>(k) * T;
    ASSERT_NEAR(s.y_clean(k), 3.0 * (t - tau + tau * std::exp(-t / tau)), 1e-12) << k;
  }
}

// A mass against a cubic spring is pushed by a constant force to x = (F/c)^(1/3),
// where the local stiffness 3 c x^2 gives wn T = 12: the explicit sampled loop
// rings up and overflows. The simulator refuses it at the sample it does, naming
// the cubic; the same mass with a soft spring stays bounded.
TEST(SimulatorOpenLoop, ADivergingCubicStiffnessIsRefusedNotWrittenAsNaN) {
  PlantSpec plant;
  plant.modes = {fixed(make_rigid_body("rigid", 0.5, 2))};
  plant.effects.cubic = 1e24;
  try {
    simulate(plant, open_loop(1e-3, Eigen::VectorXd::Ones(2000)));
    FAIL() << "a diverging simulation was returned";
  } catch (const std::domain_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("diverged at t = "), std::string::npos) << what;
    EXPECT_NE(what.find("cubic"), std::string::npos) << what;
  }
  plant.effects.cubic = 1.0;
  const SimulationResult r = simulate(plant, open_loop(1e-3, Eigen::VectorXd::Ones(2000)));
  EXPECT_TRUE(r.y_clean.allFinite());
  EXPECT_LT(r.y_clean.cwiseAbs().maxCoeff(), 2.0);  // x^3 ~ F/c = 1 within a factor
}

// Least-squares amplitude and phase of y_k = A sin(w t_k + phi) over samples.
std::complex<double> fit_sinusoid(const Eigen::VectorXd& y, const Eigen::VectorXd& t, double w) {
  Eigen::MatrixXd X(y.size(), 2);
  X.col(0) = (w * t.array()).sin().matrix();
  X.col(1) = (w * t.array()).cos().matrix();
  const Eigen::Vector2d c = X.colPivHouseholderQr().solve(y);
  return {c(0), c(1)};  // A e^{j phi} = c0 + j c1
}

// A sine through the paper's fastest mode at wT = 0.875: in steady state the
// samples are exactly |G_zoh| sin(w t_k + arg G_zoh). Against the continuous
// G(jw), the ZOH acts like a half-sample delay: G_zoh ~ G(jw) e^{-jwT/2}.
TEST(SimulatorOpenLoop, SineSteadyStateMatchesZohResponse) {
  const double w = 17.5;
  for (double T : {0.05, 0.0005}) {
    PlantSpec plant;
    plant.modes = {resonant("m", 20.0, 0.1, 1.0)};
    const Eigen::Index n = static_cast<Eigen::Index>(std::llround(40.0 / T));
    const Eigen::VectorXd t = times(n, T);
    const SimulationResult r = simulate(plant, open_loop(T, (w * t.array()).sin().matrix()));
    const std::complex<double> g = zoh_response(zoh_plant(plant_model_at(plant, 0.0), T), w, T);
    // After 25 s the transient is below e^{-2 * 25} = 2e-22 of the gain.
    const auto tail = static_cast<Eigen::Index>(std::llround(25.0 / T));
    for (Eigen::Index k = tail; k < n; ++k)
      ASSERT_NEAR(r.y_clean(k), std::abs(g) * std::sin(w * t(k) + std::arg(g)), 1e-9 * std::abs(g)) << T << " " << k;
    if (T < 0.001) {
      const std::complex<double> fitted = fit_sinusoid(r.y_clean.tail(n - tail), t.tail(n - tail), w);
      const std::complex<double> expected = plant_model_at(plant, 0.0).response(w) * std::polar(1.0, -w * T / 2.0);
      EXPECT_NEAR(std::abs(fitted - expected), 0.0, 1e-4 * std::abs(expected));
    }
  }
}

TEST(SimulatorOpenLoop, ModesAdd) {
  const double T = 0.05;
  const Eigen::VectorXd u = (0.7 * times(800, T).array()).sin().matrix() + Eigen::VectorXd::Ones(800);
  PlantSpec all = paper_plant();
  Eigen::VectorXd sum = Eigen::VectorXd::Zero(800);
  for (const PlantMode& m : all.modes) {
    PlantSpec one;
    one.modes = {m};
    sum += simulate(one, open_loop(T, u)).y_clean;
  }
  EXPECT_NEAR((simulate(all, open_loop(T, u)).y_clean - sum).cwiseAbs().maxCoeff(), 0.0, 1e-12);
}

// ---------------------------------------------------------------- time-varying

// Reference: x_k = expm(A_k T) x_{k-1} + Gamma_k u_{k-1}, y_k = gain_k x_k(0),
// with A_k, gain_k at t_k (parameters piecewise constant, switching at samples).
TEST(SimulatorTimeVarying, ModeWithTrajectoriesMatchesPerSampleReference) {
  PlantSpec plant;
  PlantMode m = resonant("m", 20.0, 0.1, 1.0);
  m.wn.points = {{2.0, 20.0}, {6.0, 15.0}};
  m.zeta.points = {{3.0, 0.1}, {5.0, 0.05}};
  m.gain.points = {{1.0, 1.0}, {4.0, 2.0}};
  plant.modes = {m};
  const double T = 0.01;
  const Eigen::Index n = 1000;
  const Eigen::VectorXd t = times(n, T);
  const Eigen::VectorXd u = (3.0 * t.array()).sin().matrix() + (19.0 * t.array()).cos().matrix();
  const SimulationResult r = simulate(plant, open_loop(T, u));

  Eigen::Vector2d x = Eigen::Vector2d::Zero();
  double u_prev = 0.0;
  for (Eigen::Index k = 0; k < n; ++k) {
    const double wn = m.wn.at(t(k), 0.0), zeta = m.zeta.at(t(k), 0.0), gain = m.gain.at(t(k), 0.0);
    Eigen::Matrix3d M = Eigen::Matrix3d::Zero();
    M << 0.0, 1.0, 0.0, -wn * wn, -2.0 * zeta * wn, wn * wn, 0.0, 0.0, 0.0;
    const Eigen::Matrix3d E = (M * T).exp();
    x = E.topLeftCorner<2, 2>() * x + E.topRightCorner<2, 1>() * u_prev;
    u_prev = u(k);
    ASSERT_NEAR(r.y_clean(k), gain * x(0), 1e-9) << k;

    ASSERT_EQ(r.truth(k, 0), wn);
    ASSERT_EQ(r.truth(k, 1), zeta);
    ASSERT_EQ(r.truth(k, 2), gain);
  }
  EXPECT_EQ(r.truth_columns, (std::vector<std::string>{"m_wn", "m_zeta", "m_gain"}));
  EXPECT_NEAR(r.truth(400, 0), 17.5, 1e-12);  // t = 4 s: halfway through the wn ramp
}

TEST(SimulatorTimeVarying, PlantModelAtAndTruthColumns) {
  PlantSpec plant = paper_plant();
  plant.modes[0].wn.points = {{100.0, 2.0}, {300.0, 1.6}};
  plant.modes.push_back(fixed(make_rigid_body("rigid", 0.5, 2)));
  const AdditiveModel m = plant_model_at(plant, 200.0);
  ASSERT_EQ(m.submodels.size(), 4u);
  EXPECT_EQ(m.submodels[0].name, "mode1");
  EXPECT_NEAR(modal_parameters(m.submodels[0]).wn, 1.8, 1e-12);
  EXPECT_NEAR(modal_parameters(m.submodels[1]).zeta, 0.025, 1e-12);
  EXPECT_EQ(m.submodels[3].rigid_poles, 2);

  const SimulationResult r = simulate(plant, open_loop(0.05, Eigen::VectorXd::Ones(10)));
  ASSERT_EQ(r.truth_columns.size(), 10u);
  EXPECT_EQ(r.truth_columns[9], "rigid_theta0");
  EXPECT_EQ(r.truth(5, 9), 0.5);
  EXPECT_EQ(r.truth.rows(), 10);
}

// ---------------------------------------------------------------- closed loop

void expect_control_law(const SimulationResult& r, const DiscreteTransferFunction& controller) {
  DiscreteTransferFunction c = controller;
  c.reset();
  const double scale = std::max(1.0, r.record.u.cwiseAbs().maxCoeff());
  for (Eigen::Index k = 0; k < r.record.size(); ++k)
    ASSERT_NEAR(c.step(r.record.r(k) - r.record.y(k)), r.record.u(k), 1e-12 * scale) << k;
}

TEST(SimulatorClosedLoop, PaperLoopFollowsControlLawAndStaysBounded) {
  PlantSpec plant = paper_plant();
  plant.noise_variance = 0.01;
  const ExperimentSpec e = closed_loop(0.05, 300.0, paper_controller(), paper_reference());
  const SimulationResult r = simulate(plant, e);
  ASSERT_EQ(r.record.size(), 6000);
  ASSERT_TRUE(r.record.has_reference());
  EXPECT_EQ(r.record.r, generate(paper_reference(), r.record.t));
  expect_control_law(r, e.controller);
  EXPECT_LT(r.record.y.cwiseAbs().maxCoeff(), 20.0);
  EXPECT_GT(r.record.y.cwiseAbs().maxCoeff(), 1.0);  // it does track the 3-unit setpoint
  // The loop is stable: the printed controller (-0.2058) is not.
  const ZohPlant g = zoh_plant(plant_model_at(plant, 0.0), 0.05);
  EXPECT_NEAR(spectral_radius(e.controller, g), 0.9956, 1e-3);
  const DiscreteTransferFunction printed({0.02329, -0.2058, 0.00454}, {1.0, -1.0, 0.0});
  EXPECT_GT(spectral_radius(printed, g), 1.2);
  const SimulationResult bad = simulate(paper_plant(), closed_loop(0.05, 100.0, printed, paper_reference()));
  EXPECT_GT(bad.record.y.cwiseAbs().maxCoeff(), 1e6);
}

// A biproper submodel closes an algebraic loop with the controller's
// feedthrough; the solved u_k must satisfy both the control law and the plant.
TEST(SimulatorClosedLoop, AlgebraicLoopWithBiproperPlant) {
  PlantSpec plant;
  plant.modes = {resonant("mode", 20.0, 0.1, 1.0), fixed(transfer_function("direct", {0.1}, {0.5, 0.02}, 0))};
  plant.noise_variance = 0.01;
  const DiscreteTransferFunction c = paper_controller();
  const double T = 0.05;
  ASSERT_LT(spectral_radius(c, zoh_plant(plant_model_at(plant, 0.0), T)), 1.0);
  const SimulationResult r = simulate(plant, closed_loop(T, 200.0, c, paper_reference()));
  expect_control_law(r, c);
  // The plant output is the open-loop response to the applied input.
  PlantSpec clean = plant;
  clean.noise_variance = 0.0;
  const SimulationResult open = simulate(clean, open_loop(T, r.record.u));
  EXPECT_NEAR((open.y_clean - r.y_clean).cwiseAbs().maxCoeff(), 0.0, 1e-12 * r.y_clean.cwiseAbs().maxCoeff());
  EXPECT_GT((r.record.y - r.y_clean).cwiseAbs().maxCoeff(), 0.0);
}

// ---------------------------------------------------------------- noise

double centred_variance(const Eigen::VectorXd& x) { return (x.array() - x.mean()).square().mean(); }

// N = 20000: the sample variance has relative std sqrt(2/N) = 1 %; bounds are 5 sigma.
TEST(SimulatorNoise, VarianceMeanAndWhiteness) {
  PlantSpec plant = paper_plant();
  plant.noise_variance = 0.04;
  const double T = 0.05;
  const Eigen::Index n = 20000;
  const SimulationResult r = simulate(plant, open_loop(T, (2.0 * times(n, T).array()).sin().matrix()));
  const Eigen::VectorXd v = r.record.y - r.y_clean;
  EXPECT_EQ(r.noise_variance, 0.04);
  EXPECT_NEAR(centred_variance(v), 0.04, 0.05 * 0.04);
  EXPECT_NEAR(v.mean(), 0.0, 5.0 * std::sqrt(0.04 / n));
  const double lag1 = v.head(n - 1).dot(v.tail(n - 1)) / v.squaredNorm();
  EXPECT_NEAR(lag1, 0.0, 5.0 / std::sqrt(static_cast<double>(n)));
}

TEST(SimulatorNoise, SnrSetsVarianceFromNoiseFreeOutput) {
  PlantSpec plant = paper_plant();
  plant.snr_db = 20.0;
  const double T = 0.05;
  const Eigen::Index n = 20000;
  const SimulationResult r = simulate(plant, open_loop(T, (2.0 * times(n, T).array()).sin().matrix()));
  const double p_signal = centred_variance(r.y_clean);
  EXPECT_NEAR(r.noise_variance, p_signal / 100.0, 1e-12 * p_signal);
  const double realised_snr = 10.0 * std::log10(p_signal / centred_variance(r.record.y - r.y_clean));
  EXPECT_NEAR(realised_snr, 20.0, 0.25);  // 5 sigma of the variance estimate is 0.22 dB

  // Closed loop: the power is that of the noise-free closed-loop run.
  PlantSpec noisy = paper_plant();
  noisy.snr_db = 30.0;
  const ExperimentSpec e = closed_loop(T, 200.0, paper_controller(), paper_reference());
  const SimulationResult cl = simulate(noisy, e);
  const SimulationResult noise_free = simulate(paper_plant(), e);
  EXPECT_NEAR(cl.noise_variance, centred_variance(noise_free.y_clean) / 1000.0, 1e-12);
  expect_control_law(cl, e.controller);
}

TEST(SimulatorNoise, SeedReproducible) {
  PlantSpec plant = paper_plant();
  plant.noise_variance = 0.01;
  ExperimentSpec e = closed_loop(0.05, 50.0, paper_controller(), paper_reference());
  e.seed = 5;
  const SimulationResult a = simulate(plant, e), b = simulate(plant, e);
  EXPECT_EQ(a.record.y, b.record.y);
  EXPECT_EQ(a.record.u, b.record.u);
  e.seed = 6;
  EXPECT_GT((simulate(plant, e).record.y - a.record.y).norm(), 0.1);
}

TEST(SimulatorErrors, RejectsInvalidSpecs) {
  PlantSpec plant = paper_plant();
  ExperimentSpec e = open_loop(0.05, Eigen::VectorXd::Ones(10));
  EXPECT_THROW(simulate(PlantSpec{}, e), std::invalid_argument);
  e.excitation_samples = Eigen::VectorXd::Ones(9);  // not one per sample
  EXPECT_THROW(simulate(plant, e), std::invalid_argument);
  ExperimentSpec c = closed_loop(0.05, 1.0, DiscreteTransferFunction(), paper_reference());
  EXPECT_THROW(simulate(plant, c), std::invalid_argument);
  plant.noise_variance = -1.0;
  EXPECT_THROW(simulate(plant, open_loop(0.05, Eigen::VectorXd::Ones(10))), std::invalid_argument);
}

// ---------------------------------------------------------------- shipped configurations

std::string config_path(const std::string& name) { return test_support::source_file("config/" + name); }

// The designed loops are stable with margin over the whole trajectory.
void expect_robust_loop(const Config& config, const std::vector<double>& instants, double min_return,
                        double min_pm_deg) {
  ASSERT_TRUE(config.plant.has_value());
  for (double t : instants) {
    const ZohPlant g = zoh_plant(plant_model_at(*config.plant, t), config.sample_time);
    EXPECT_LT(spectral_radius(config.controller, g), 1.0) << config.source << " t=" << t;
    const Margins m = margins(config.controller, g, config.sample_time);
    EXPECT_GT(m.min_return, min_return) << config.source << " t=" << t;
    EXPECT_GT(m.min_phase_margin, min_pm_deg) << config.source << " t=" << t;
  }
}

TEST(SimulatorConfigs, FlexibleBeamLoopIsStableWithMargins) {
  const Config c = load_config(config_path("flexible-beam.yaml"));
  EXPECT_EQ(c.sample_time, 1.0 / 4096.0);
  ASSERT_EQ(c.model.submodels.size(), 2u);
  EXPECT_EQ(c.submodel_settings[0].forgetting, 0.9999);
  EXPECT_EQ(c.submodel_settings[1].forgetting, 0.999);
  // min |1 + L| >= 0.5 bounds the gain margin to >= 6 dB and the phase margin to >= 29 deg.
  expect_robust_loop(c, {0.0, 70.0, 150.0}, 0.5, 30.0);
  const AdditiveModel before = plant_model_at(*c.plant, 40.0), after = plant_model_at(*c.plant, 100.0);
  EXPECT_NEAR(modal_parameters(after.submodels[1]).wn / modal_parameters(before.submodels[1]).wn, 0.85, 1e-12);
}

TEST(SimulatorConfigs, MotionStageLoopIsStableWithMargins) {
  const Config c = load_config(config_path("motion-stage.yaml"));
  EXPECT_EQ(c.sample_time, 1e-4);
  ASSERT_EQ(c.model.submodels.size(), 3u);
  EXPECT_EQ(c.model.submodels[0].rigid_poles, 2);
  expect_robust_loop(c, {0.0}, 0.5, 40.0);
}

// Every shipped configuration with a simulation section runs (shortened)
// to finite data that obeys its control law.
TEST(SimulatorConfigs, EveryShippedConfigSimulates) {
  int simulated = 0;
  for (const auto& entry : std::filesystem::directory_iterator(config_path(""))) {
    if (entry.path().extension() != ".yaml") continue;
    const Config c = load_config(entry.path().string());
    if (!c.plant || !c.experiment) continue;
    ExperimentSpec e = *c.experiment;
    e.duration = std::min(e.duration, 2000.0 * e.sample_time);
    const auto n = static_cast<Eigen::Index>(std::llround(e.duration / e.sample_time));
    if (e.excitation_samples.size() > 0) e.excitation_samples = e.excitation_samples.head(n).eval();
    const SimulationResult r = simulate(*c.plant, e);
    EXPECT_EQ(r.record.size(), n) << entry.path();
    EXPECT_TRUE(r.record.y.allFinite() && r.record.u.allFinite()) << entry.path();
    EXPECT_TRUE(r.truth.allFinite()) << entry.path();
    if (e.closed_loop) expect_control_law(r, e.controller);
    ++simulated;
  }
  EXPECT_GE(simulated, 3);
}

}  // namespace
}  // namespace modalwatch
