#pragma once
// Helpers shared by the test suites: running the real modalwatch binary, and
// expanding an additive model into its unfactored B/A.
#include <array>
#include <cstdio>
#include <string>
#include <sys/wait.h>

#include <Eigen/Core>

#include "modalwatch/model.hpp"

namespace modalwatch::test_support {

struct Outcome {
  int code;
  std::string output;  // stdout and stderr
};

// Runs `modalwatch <args>` and collects its exit code and output.
inline Outcome run_cli(const std::string& args) {
  const std::string cmd = std::string(MODALWATCH_CLI) + " " + args + " 2>&1";
  FILE* pipe = popen(cmd.c_str(), "r");
  std::string out;
  std::array<char, 4096> buf{};
  while (pipe && std::fgets(buf.data(), buf.size(), pipe)) out += buf.data();
  const int status = pipe ? pclose(pipe) : -1;
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}

// Product of two polynomials in ascending coefficients.
inline Eigen::VectorXd multiply(const Eigen::VectorXd& x, const Eigen::VectorXd& y) {
  Eigen::VectorXd z = Eigen::VectorXd::Zero(x.size() + y.size() - 1);
  for (Eigen::Index i = 0; i < x.size(); ++i) z.segment(i, y.size()) += x(i) * y;
  return z;
}

// sum_i B_i/A_i as one B/A: A = prod A_i, B = sum_i B_i prod_{j != i} A_j (no rigid poles).
inline void expand(const AdditiveModel& m, Eigen::VectorXd& A, Eigen::VectorXd& B) {
  A = Eigen::VectorXd::Ones(1);
  for (const auto& s : m.submodels) A = multiply(A, s.a_polynomial());
  B = Eigen::VectorXd::Zero(A.size() - 2);
  for (std::size_t i = 0; i < m.submodels.size(); ++i) {
    Eigen::VectorXd term = m.submodels[i].b;
    for (std::size_t j = 0; j < m.submodels.size(); ++j)
      if (j != i) term = multiply(term, m.submodels[j].a_polynomial());
    B.head(term.size()) += term;
  }
}

}  // namespace modalwatch::test_support
