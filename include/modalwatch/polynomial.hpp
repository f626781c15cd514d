#pragma once
// Polynomials in p with real coefficients, stored in ascending powers:
// c(0) + c(1) p + ... + c(n) p^n.
#include <optional>

#include <Eigen/Core>

namespace modalwatch {

// Roots of c (leading coefficient c(n) != 0), via the companion matrix.
Eigen::VectorXcd roots(const Eigen::VectorXd& ascending);

// Eigenvalues of a real square matrix, or nullopt when the QR iteration does
// not converge. Eigen's EigenSolver is instantiated in polynomial.cpp alone:
// each instantiation costs 25-35 s of CPU to compile (95 s under ASan at -O2).
std::optional<Eigen::VectorXcd> eigenvalues(const Eigen::MatrixXd& A);

// Real polynomial with the given roots (conjugate pairs must be complete),
// scaled so that its constant coefficient is `constant` (anti-monic for 1).
Eigen::VectorXd polynomial_from_roots(const Eigen::VectorXcd& roots, double constant = 1.0);

// Stability projection (section 4.7): reflects every root
// with a non-negative real part into the open left half plane (s -> -conj(s)),
// which keeps |A(jw)|. `a` holds a_1..a_n of an anti-monic A(p) and is changed in
// place. Roots on the imaginary axis are moved to real part -margin*|s|.
// Returns true when anything was reflected.
bool project_stable(Eigen::VectorXd& a, double margin = 1e-6);

// True when every root of the anti-monic A(p) = 1 + a_1 p + ... + a_n p^n lies
// in the open left half plane (Routh-Hurwitz, no root finding).
bool is_hurwitz(const Eigen::VectorXd& a);

// True when a root of the anti-monic A(p) lies in the open right half plane
// (real part above tolerance |s|): unstable, not merely on the imaginary axis
// (which is_hurwitz rejects too). Non-finite coefficients count as unstable.
bool is_unstable(const Eigen::VectorXd& a, double tolerance = 1e-9);

}  // namespace modalwatch
