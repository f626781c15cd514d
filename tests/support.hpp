#pragma once
// Helpers shared by the test suites: running the real modalwatch binary, and
// expanding an additive model into its unfactored B/A.
#include <sys/wait.h>
#include <unistd.h>
#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>

#include <gtest/gtest.h>

#include <Eigen/Core>

#include "modalwatch/error.hpp"
#include "modalwatch/model.hpp"

namespace modalwatch::test_support {

struct Outcome {
  int code;
  std::string output;  // stdout and stderr
};

// A file of the source tree, or of the shared measured records, by its path
// below them. Appended rather than std::string(dir) + "/...": GCC 12 warns of
// a bounds overflow in that (a false positive, -Werror=array-bounds) where
// the precompiled header moves its inlining.
inline std::string source_file(const std::string& relative) {
  std::string path = MODALWATCH_SOURCE_DIR;
  path += '/';
  path += relative;
  return path;
}
inline std::string shared_file(const std::string& relative) {
  std::string path = MODALWATCH_SHARED_DATA;
  path += '/';
  path += relative;
  return path;
}

// Runs `modalwatch <args>` and collects its exit code and output.
inline Outcome run_cli(const std::string& args) {
  std::string cmd = MODALWATCH_CLI;
  cmd += ' ';
  cmd += args;
  cmd += " 2>&1";
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

// A fixture with a fresh directory per test, removed afterwards.
class ScratchDir : public ::testing::Test {
 public:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("modalwatch_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->test_suite_name() + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  std::string write(const std::string& name, const std::string& text) const {
    std::ofstream(path(name)) << text;
    return path(name);
  }

 protected:
  std::filesystem::path dir_;
};

// The message of the InputError thrown by f (fails the test when none is thrown).
inline std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const InputError& e) {
    return e.what();
  }
  ADD_FAILURE() << "expected an InputError";
  return "";
}

}  // namespace modalwatch::test_support
