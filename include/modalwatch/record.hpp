#pragma once
// Sampled input/output data: one sample, and a record of many. t, u, y and, in
// closed loop, the reference r; with several actuators, the further inputs.
#include <array>
#include <cstddef>
#include <vector>

#include <Eigen/Core>

namespace modalwatch {

// The most measured inputs a Sample carries, and so the most the recursive
// estimator, `track` and the daemon take (the estimator and the config refuse a
// model with more). Fixed, so that a sample stays a plain value that is copied
// and queued without allocation.
inline constexpr int kMaxInputs = 8;

// One sample as the recursive estimator takes it (t in s). With several
// measured inputs, u is the first and further_u[0 .. further_inputs) the others,
// in the model's order (AdditiveModel::inputs).
struct Sample {
  double t = 0.0, u = 0.0, y = 0.0, r = 0.0;
  int further_inputs = 0;
  std::array<double, kMaxInputs - 1> further_u{};

  int inputs() const noexcept { return 1 + further_inputs; }
  // Input j: u for j = 0, else further_u[j - 1] (j < inputs(), unchecked).
  double input(int j) const noexcept { return j == 0 ? u : further_u[static_cast<std::size_t>(j - 1)]; }
};

struct Record {
  Eigen::VectorXd t;  // s, strictly increasing, equidistant
  Eigen::VectorXd u;  // plant input (controller output in closed loop)
  Eigen::VectorXd y;  // measured output
  Eigen::VectorXd r;  // reference; empty in open loop
  // Further measured inputs u_2, u_3, ... (several actuators), each as long as
  // u; empty for a single input. u stays the first input.
  std::vector<Eigen::VectorXd> further_u;

  Eigen::Index size() const { return t.size(); }
  int inputs() const { return 1 + static_cast<int>(further_u.size()); }
  // Input j: u for j = 0, else further_u[j - 1].
  const Eigen::VectorXd& input(int j) const { return j == 0 ? u : further_u[static_cast<std::size_t>(j - 1)]; }
  bool has_reference() const { return r.size() == t.size() && r.size() > 0; }
  // Mean sample interval; records are assumed equidistant (the CSV reader checks).
  double sample_time() const {
    return t.size() > 1 ? (t(t.size() - 1) - t(0)) / static_cast<double>(t.size() - 1) : 0.0;
  }
  // Samples [begin, begin+count).
  Record segment(Eigen::Index begin, Eigen::Index count) const {
    Record s;
    s.t = t.segment(begin, count);
    s.u = u.segment(begin, count);
    s.y = y.segment(begin, count);
    if (has_reference()) s.r = r.segment(begin, count);
    for (const auto& v : further_u) s.further_u.push_back(v.segment(begin, count));
    return s;
  }
};

}  // namespace modalwatch
