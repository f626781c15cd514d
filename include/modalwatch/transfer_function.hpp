#pragma once
// Discrete-time transfer functions in the forward shift operator q, such as the
// controller C_d(q) of eq. (9):
//
//   C_d(q) = (b_0 q^nb + ... + b_nb) / (a_0 q^na + ... + a_na),   nb <= na,
//
// coefficients in descending powers of q, as printed in the paper.
#include <complex>
#include <vector>

#include <Eigen/Core>

namespace modalwatch {

class DiscreteTransferFunction {
 public:
  DiscreteTransferFunction() = default;
  // Throws std::invalid_argument when improper (nb > na) or a_0 == 0.
  DiscreteTransferFunction(std::vector<double> numerator, std::vector<double> denominator);

  // Output at t_k for input e_k (direct form II transposed; biproper allowed).
  // Inline, like peek() and feedthrough(): the recursive estimator runs the
  // controller of its instrument loop (eq. 29) at every sample.
  double step(double e) {
    if (den_.empty()) return 0.0;
    const double y = peek(e);
    const std::size_t n = z_.size();
    if (n == 0) return y;
    double* z = z_.data();
    const double* b = num_.data();
    const double* a = den_.data();
    // DF2T: z_i <- z_{i+1} + b_{i+1} e - a_{i+1} y, with z_n = 0.
    for (std::size_t i = 0; i + 1 < n; ++i) z[i] = z[i + 1] + b[i + 1] * e - a[i + 1] * y;
    z[n - 1] = b[n] * e - a[n] * y;
    return y;
  }
  void reset();
  bool empty() const { return den_.empty(); }

  // The output if the input at t_k were e, without advancing the state: lets a
  // closed loop with a biproper controller and a strictly proper plant be solved
  // sample by sample.
  double peek(double e) const {
    if (den_.empty()) return 0.0;
    return num_[0] * e + (z_.empty() ? 0.0 : z_[0]);
  }
  // Direct feedthrough b_0 / a_0 (after alignment of degrees).
  double feedthrough() const { return num_.empty() ? 0.0 : num_[0]; }

  std::complex<double> response(double w, double T) const;  // C_d(e^{j w T})
  // The same filter (coefficients); the states may differ.
  bool operator==(const DiscreteTransferFunction& other) const { return num_ == other.num_ && den_ == other.den_; }

  const std::vector<double>& numerator() const { return num_; }
  const std::vector<double>& denominator() const { return den_; }

  // Internal state, for checkpoints and tests.
  const std::vector<double>& state() const { return z_; }
  void set_state(const std::vector<double>& z);

 private:
  std::vector<double> num_;  // aligned to den_ length, normalised by a_0
  std::vector<double> den_;
  std::vector<double> z_;
};

// Poles of the closed loop formed by a discrete controller and the ZOH
// equivalent of a continuous-time plant given as a state-space model; returns
// the largest pole magnitude. Used to check that a configured loop is stable.
double closed_loop_spectral_radius(const DiscreteTransferFunction& controller, const Eigen::MatrixXd& plant_phi,
                                   const Eigen::MatrixXd& plant_gamma, const Eigen::MatrixXd& plant_c, double plant_d);

}  // namespace modalwatch
