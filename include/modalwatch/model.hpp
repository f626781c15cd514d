#pragma once
// The additive continuous-time model of eqs. (5) and (8) of the paper:
//
//   G(p) = sum_i G_i(p),   G_i(p) = B_i(p) / (p^l_i A_i(p)),
//   A_i(p) = a_{i,n} p^n + ... + a_{i,1} p + 1     (anti-monic, eq. 6)
//   B_i(p) = b_{i,m} p^m + ... + b_{i,1} p + b_{i,0}
//
// with l_i poles at the origin for rigid-body submodels (section 4.6).
// Coefficients are in physical units (time in seconds).
//
// The sensor may measure a derivative of the position: the output is then
// p^z G_i u (z = 1 velocity, z = 2 acceleration). B_i, A_i and l_i keep
// describing the position response, so that wn, zeta and the DC gain b_0 keep
// their meaning whatever the sensor (b_0 in output units * s^z per input unit).
#include <complex>
#include <optional>
#include <string>
#include <string_view>
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

// What the sensor measures: the position response differentiated z times.
inline constexpr int kMaxOutputDerivatives = 2;
// "position", "velocity", "acceleration" for z = 0, 1, 2.
const char* output_kind_name(int output_derivatives);
// z of a kind's name; none for another name.
std::optional<int> output_derivatives_of(std::string_view kind);

struct Submodel {
  std::string name;
  int n = 2;            // order of A
  int m = 0;            // order of B, m + z <= n + l
  int rigid_poles = 0;  // l: poles at the origin
  // z: the measured output is p^z B / (p^l A) u, the position response
  // differentiated z times (0 position, 1 velocity, 2 acceleration).
  int output_derivatives = 0;
  Eigen::VectorXd a;    // a_1 .. a_n
  Eigen::VectorXd b;    // b_0 .. b_m
  // The measured input that drives this submodel: an index into the model's
  // inputs (AdditiveModel::inputs). 0, the first input, for a single-input model.
  int input = 0;
  // One resonance seen through several inputs: the name of the submodel whose
  // A(p) this one shares, empty when it has its own. A structure's mode has
  // one pole pair and a residue per actuator, so the batch fits (fit_srivc)
  // estimate a shared A from every member's input at once; the recursive
  // estimator follows each submodel's poles on their own.
  std::string poles_of;

  int n_theta() const { return n + m + 1; }
  // eq. (7): theta_i = [a_1 .. a_n, b_0 .. b_m]
  Eigen::VectorXd theta() const;
  void set_theta(const Eigen::VectorXd& theta);

  // Ascending coefficients of A(p): [1, a_1, ..., a_n].
  Eigen::VectorXd a_polynomial() const;
  // Ascending coefficients of the full denominator p^l A(p).
  Eigen::VectorXd denominator() const;
  // Ascending coefficients of the measured output's numerator p^z B(p)
  // (size m + z + 1): over denominator() it gives the output from the same
  // filter states as the position B / (p^l A), exactly, also where p^z and
  // p^l cancel (the top derivative of 1/(p^l A) is algebraic in the input).
  Eigen::VectorXd output_numerator() const;

  // The measured response p^z G_i(p) at p = j w, w in rad/s, with the common
  // powers of p cancelled (a rigid body b0/p^2 measured as acceleration is b0 at w = 0 too).
  std::complex<double> response(double w) const;

  // True when this is a plain second-order mode (n = 2, m = 0, no rigid poles),
  // whatever the sensor measures.
  bool is_mode() const { return n == 2 && m == 0 && rigid_poles == 0; }
  // True for a mode with a real residue (is_mode) or a complex one, numerator
  // b0 + b1 p: a resonance that modal_parameters describes by wn, zeta and DC gain.
  bool is_resonance() const { return n == 2 && m <= 1 && rigid_poles == 0; }
  // True for a constant measured response b0 (no poles left after p^z cancels
  // p^l): a static gain, feedthrough, or a rigid body seen by an accelerometer.
  bool is_feedthrough() const { return n == 0 && m == 0 && rigid_poles == output_derivatives; }
  // Throws std::invalid_argument when the sizes do not match n, m, or the
  // measured response p^z B / (p^l A) is improper.
  void check() const;
  // Same name, orders, output kind, coefficients, input and shared poles.
  bool operator==(const Submodel& other) const;
};

// A resonant mode b0 / (p^2/wn^2 + 2 zeta/wn p + 1), measured as its z-th derivative.
Submodel make_mode(const std::string& name, const ModalParameters& modal, int output_derivatives = 0);
// A rigid body b0 / p^l; with l = 0 the feedthrough b0.
Submodel make_rigid_body(const std::string& name, double gain, int rigid_poles = 2, int output_derivatives = 0);

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
// J = d(wn, zeta, gain) / d(a1, a2, b0), the map modal_covariance() applies;
// gain's row alone where a2 <= 0 (no resonance).
Eigen::Matrix3d modal_jacobian(double a1, double a2);
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

  // z of the submodels (one sensor: all measure the same kind); 0 without submodels.
  int output_derivatives() const { return submodels.empty() ? 0 : submodels.front().output_derivatives; }
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

// The submodels that share one A(p): per submodel that has its own poles, its
// index followed by those of the submodels whose poles_of names it, in model
// order. Throws std::invalid_argument naming the submodel when poles_of names
// no submodel, one that shares another's poles itself, one of other orders or
// output kind, or one on the same input.
std::vector<std::vector<int>> pole_groups(const AdditiveModel& model);

// The parameters of a model whose submodels may share poles: beta without the
// a of each submodel that shares another's (its leader's a stands for it).
// Equal to beta when no submodel shares poles.
Eigen::VectorXd free_beta(const AdditiveModel& model);
// Sets beta from them: each sharing submodel takes its leader's a.
void set_free_beta(AdditiveModel& model, const Eigen::VectorXd& p);
// E with beta = E * free_beta(model) (0/1 entries): a covariance of the free
// parameters C maps to E C E^T over beta.
Eigen::MatrixXd free_beta_map(const AdditiveModel& model);

}  // namespace modalwatch
