#pragma once
// The additive continuous-time model of eqs. (5) and (8) of the paper:
//
//   G(p) = sum_i G_i(p),   G_i(p) = B_i(p) / (p^l_i A_i(p)),
//   A_i(p) = a_{i,n} p^n + ... + a_{i,1} p + 1     (anti-monic, eq. 6)
//   B_i(p) = b_{i,m} p^m + ... + b_{i,1} p + b_{i,0}
//
// with l_i poles at the origin for rigid-body submodels (section 4.6).
// Coefficients are in physical units (time in seconds).
#include <complex>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace modalwatch {

// Natural frequency, damping ratio and DC gain of b0 / (p^2/wn^2 + 2 zeta/wn p + 1),
// eq. (11). For a rigid-body submodel b0/p^l only `gain` is meaningful.
struct ModalParameters {
  double wn = 0.0;    // rad/s
  double zeta = 0.0;  // -
  double gain = 0.0;  // DC gain (b0), output units per input unit

  double hz() const;  // wn / (2 pi)
  bool operator==(const ModalParameters&) const = default;
};

struct Submodel {
  std::string name;
  int n = 2;            // order of A
  int m = 0;            // order of B, m <= n (+l for rigid bodies)
  int rigid_poles = 0;  // l: poles at the origin
  Eigen::VectorXd a;    // a_1 .. a_n
  Eigen::VectorXd b;    // b_0 .. b_m
  // The measured input that drives this submodel: an index into the model's
  // inputs (AdditiveModel::inputs). 0, the first input, for a single-input model.
  int input = 0;

  int n_theta() const { return n + m + 1; }
  // eq. (7): theta_i = [a_1 .. a_n, b_0 .. b_m]
  Eigen::VectorXd theta() const;
  void set_theta(const Eigen::VectorXd& theta);

  // Ascending coefficients of A(p): [1, a_1, ..., a_n].
  Eigen::VectorXd a_polynomial() const;
  // Ascending coefficients of the full denominator p^l A(p).
  Eigen::VectorXd denominator() const;

  // G_i(j w), w in rad/s.
  std::complex<double> response(double w) const;

  // True when this is a plain second-order mode (n = 2, m = 0, no rigid poles).
  bool is_mode() const { return n == 2 && m == 0 && rigid_poles == 0; }
  // True for a mode with a real residue (is_mode) or a complex one, numerator
  // b0 + b1 p: a resonance that modal_parameters describes by wn, zeta and DC gain.
  bool is_resonance() const { return n == 2 && m <= 1 && rigid_poles == 0; }
  // True for a constant G = b0 (no poles at all): a static gain, or feedthrough.
  bool is_feedthrough() const { return n == 0 && m == 0 && rigid_poles == 0; }
  // Throws std::invalid_argument when the sizes do not match n, m.
  void check() const;
  // Same name, orders, coefficients and input.
  bool operator==(const Submodel& other) const;
};

// A resonant mode b0 / (p^2/wn^2 + 2 zeta/wn p + 1).
Submodel make_mode(const std::string& name, const ModalParameters& modal);
// A rigid body b0 / p^l; with l = 0 the feedthrough b0.
Submodel make_rigid_body(const std::string& name, double gain, int rigid_poles = 2);

// The modal view of a second-order submodel (n = 2). For m > 0 the gain is b0,
// still the DC gain. For a rigid body, wn and zeta are those of A (0 if n < 2).
ModalParameters modal_parameters(const Submodel& s);

// Covariance of (wn, zeta, gain) from the covariance of theta_i, by first-order
// propagation J C J' through the maps of eq. (11): wn = a2^{-1/2},
// zeta = a1 / (2 sqrt(a2)), gain = b0. Only gain's row and column are filled for
// a submodel that is not a plain mode with a2 > 0; zero when the sizes disagree.
Eigen::Matrix3d modal_covariance(const Submodel& s, const Eigen::MatrixXd& theta_covariance);
// The same from A's coefficients a1, a2 and the covariance of (a1, a2, b0).
// Fixed size, no allocation (for per-sample callers).
Eigen::Matrix3d modal_covariance(double a1, double a2, const Eigen::Matrix3d& a1_a2_b0_covariance);
// Standard deviations of (wn, zeta, gain): the square roots of modal_covariance's diagonal.
ModalParameters modal_std(const Submodel& s, const Eigen::MatrixXd& theta_covariance);

// Every resonance of a submodel of any order: the (wn, zeta) of each
// complex-conjugate root pair of A, and real roots as zeta >= 1 entries, sorted by wn.
std::vector<ModalParameters> resonances(const Submodel& s);

// Several measured inputs (actuators): the output is the sum of every
// submodel driven by its own input, y = sum_i G_i(p) u_{input(i)}.
struct AdditiveModel {
  std::vector<Submodel> submodels;
  // Names of the measured inputs (record columns) the submodels' `input`
  // indexes; empty for a single input, which is then unnamed.
  std::vector<std::string> inputs;

  // Number of measured inputs: 1 when `inputs` is empty.
  int n_inputs() const { return inputs.empty() ? 1 : static_cast<int>(inputs.size()); }
  // The name of input j, or `fallback` when the model names none.
  std::string input_name(int j, const std::string& fallback = "u") const {
    return j < static_cast<int>(inputs.size()) ? inputs[static_cast<std::size_t>(j)] : fallback;
  }

  int n_beta() const;  // sum of n_theta
  // eq. (8): beta = [theta_1; ...; theta_K]
  Eigen::VectorXd beta() const;
  void set_beta(const Eigen::VectorXd& beta);
  // Offset of theta_i inside beta.
  int offset(int i) const;
  // G(j w): every submodel, the response of a single-input model.
  std::complex<double> response(double w) const;
  // From input `input` alone: the submodels it drives.
  std::complex<double> response(double w, int input) const;
  bool operator==(const AdditiveModel&) const = default;
};

}  // namespace modalwatch
