// diagnose's output-error refinement (src/diagnose/output_error.hpp: our
// Levenberg-Marquardt, forward-difference Jacobian, parameters scaled by their
// start) against Eigen's LevenbergMarquardt (MINPACK's lmder with Eigen's
// NumericalDiff) on the same problems, from the same start, in the same scaled
// parameters. Measured and reported, never asserted: the counters are the
// final output-error cost relative to the start's (cost_ratio) and the number
// of simulations of the model (simulations).
//
//   BM_Ours/case, BM_EigenLM/case   case 0: 2 modes + cubic stiffness, open loop
//                                   case 1: 2 modes + Coulomb friction, closed loop
//                                   case 2: 3 modes, open loop, 5-20 % off
//                                   case 3: 2 modes, open loop, 18 % off in
//                                           frequency, damping twice the truth
#include <cmath>
#include <numbers>
#include <random>
#include <utility>

#include <benchmark/benchmark.h>
#include <unsupported/Eigen/LevenbergMarquardt>
#include <unsupported/Eigen/NumericalDiff>

#include "modalwatch/diagnose.hpp"
#include "modalwatch/simulator.hpp"
#include "output_error.hpp"

namespace modalwatch {
namespace {

using namespace diagnose_detail;

constexpr double kT = 0.01;

struct Case {
  Record data;
  LoopSpec loop;
  AugmentedModel start;
};

Case make_case(int which) {
  PlantSpec plant;
  for (const auto& [name, p] :
       {std::pair{"m1", ModalParameters{5.0, 0.05, 1.0}}, std::pair{"m2", ModalParameters{20.0, 0.03, 0.5}}}) {
    PlantMode m;
    m.modal = p;
    m.submodel = make_mode(name, p);
    plant.modes.push_back(m);
  }
  plant.noise_variance = 1e-4;
  Case c;
  c.start.linear.submodels = {make_mode("m1", {5.3, 0.08, 0.8}), make_mode("m2", {19.0, 0.05, 0.6})};
  ExperimentSpec ex;
  ex.sample_time = kT;
  ex.duration = 30.0;
  ex.seed = 11;
  ex.excitation.kind = SignalSpec::Kind::multisine;
  ex.excitation.f_min_hz = 0.1;
  ex.excitation.f_max_hz = 10.0;
  ex.excitation.period_s = 10.0;
  ex.excitation.rms = 1.0;
  if (which == 0) {
    plant.effects.cubic = 0.02;
    c.start.effects.cubic_on = true;
    c.start.effects.cubic = 0.01;
  } else if (which == 1) {
    plant.effects.coulomb = 0.3;
    ex.closed_loop = true;
    ex.controller = DiscreteTransferFunction({0.5 + 0.04 / kT, -0.04 / kT}, {1.0, 0.0});
    c.loop.closed = true;
    c.loop.controller = ex.controller;
    c.start.effects.coulomb_on = true;
    c.start.effects.coulomb = 0.2;
  } else if (which == 3) {
    c.start.linear.submodels = {make_mode("m1", {5.9, 0.1, 0.6}), make_mode("m2", {16.5, 0.06, 0.8})};
  } else {
    PlantMode m;
    m.modal = {60.0, 0.02, 0.3};
    m.submodel = make_mode("m3", m.modal);
    plant.modes.push_back(m);
    c.start.linear.submodels.push_back(make_mode("m3", {57.0, 0.03, 0.25}));
  }
  c.data = simulate(plant, ex).record;
  return c;
}

void report(benchmark::State& state, double start_cost, double cost, long simulations) {
  state.counters["cost_ratio"] = cost / start_cost;
  state.counters["simulations"] = static_cast<double>(simulations);
}

void BM_Ours(benchmark::State& state) {
  const Case c = make_case(static_cast<int>(state.range(0)));
  long simulations = 0;
  const Problem pb{c.data, c.loop, &simulations};
  const double start_cost = cost_of(output(c.start, pb), c.data.y);
  double cost = 0.0;
  for (auto _ : state) {
    simulations = 0;
    cost = refine(c.start, pb, 40).cost;
  }
  report(state, start_cost, cost, simulations);
}

struct OutputErrorFunctor : Eigen::DenseFunctor<double> {
  const AugmentedModel& start;
  const Problem& pb;
  Eigen::VectorXd p0, scale;
  OutputErrorFunctor(const AugmentedModel& s, const Problem& p, const Eigen::VectorXd& p0_, const Eigen::VectorXd& sc)
      : DenseFunctor<double>(static_cast<int>(p0_.size()), static_cast<int>(p.data.size())),
        start(s),
        pb(p),
        p0(p0_),
        scale(sc) {}
  int operator()(const Eigen::VectorXd& delta, Eigen::VectorXd& f) const {
    AugmentedModel m = start;
    unpack(p0 + scale.cwiseProduct(delta), m);
    const Eigen::VectorXd y = output(m, pb);
    if (y.size() != pb.data.y.size())
      f.setConstant(1e10);
    else
      f = pb.data.y - y;
    return 0;
  }
};

void BM_EigenLM(benchmark::State& state) {
  const Case c = make_case(static_cast<int>(state.range(0)));
  long simulations = 0;
  const Problem pb{c.data, c.loop, &simulations};
  const double start_cost = cost_of(output(c.start, pb), c.data.y);
  const Eigen::VectorXd p0 = pack(c.start);
  const Eigen::VectorXd scale = p0.cwiseAbs();
  double cost = 0.0;
  for (auto _ : state) {
    simulations = 0;
    OutputErrorFunctor f(c.start, pb, p0, scale);
    Eigen::NumericalDiff<OutputErrorFunctor> diff(f, 1e-12);  // step sqrt(1e-12) |x|, 1e-6 as ours
    Eigen::LevenbergMarquardt<Eigen::NumericalDiff<OutputErrorFunctor>> lm(diff);
    lm.setMaxfev(40 * (static_cast<int>(p0.size()) + 1));
    Eigen::VectorXd delta = Eigen::VectorXd::Zero(p0.size());
    lm.minimize(delta);
    AugmentedModel m = c.start;
    unpack(p0 + scale.cwiseProduct(delta), m);
    cost = cost_of(output(m, pb), c.data.y);
  }
  report(state, start_cost, cost, simulations);
}

BENCHMARK(BM_Ours)->DenseRange(0, 3)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_EigenLM)->DenseRange(0, 3)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace modalwatch

BENCHMARK_MAIN();
