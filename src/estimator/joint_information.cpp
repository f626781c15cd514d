// JointInformation's sizing, rescaling and solve (joint_information.hpp): off
// the per-sample path, or once every kSolveEvery updates on it.
#include "joint_information.hpp"

#include <algorithm>
#include <cmath>

namespace modalwatch::detail {

void JointInformation::resize(const std::vector<Block>& blocks) {
  offset_.assign(blocks.size(), 0);
  n_ = 0;
  for (std::size_t i = 0; i < blocks.size(); ++i) {
    offset_[i] = n_;
    n_ += blocks[i].nt;
  }
  S_.resize(n_, n_);
  inv_w_.resize(n_);
  v_.resize(n_);
  S_good_.resize(n_, n_);
  inv_w_good_.resize(n_);
  A_.resize(n_, n_);
  own_.resize(n_, n_);
  inverse_.setZero(n_, n_);
  prior_.setZero(n_);
  solved_ = current_ = false;
  clear();
  save_good();
}

void JointInformation::clear() {
  S_.setZero();
  inv_w_.setOnes();
  updates_ = solved_at_ = 0;
  countdown_ = gap_ = 1;
  current_ = false;
}

void JointInformation::rescale_weights() {
  for (int q = 0; q < n_; ++q)
    for (int r = 0; r < n_; ++r) S_(r, q) /= inv_w_(r) * inv_w_(q);
  inv_w_.setOnes();
}

void JointInformation::save_good() {
  S_good_ = S_;
  inv_w_good_ = inv_w_;
  updates_good_ = updates_;
}

void JointInformation::restore_good() {
  S_ = S_good_;
  inv_w_ = inv_w_good_;
  updates_ = solved_at_ = updates_good_;
  current_ = false;
}

JointInformation::Saved JointInformation::saved() const {
  Saved s;
  s.information = inv_w_.cwiseInverse().asDiagonal() * S_ * inv_w_.cwiseInverse().asDiagonal();
  s.good_information = inv_w_good_.cwiseInverse().asDiagonal() * S_good_ * inv_w_good_.cwiseInverse().asDiagonal();
  s.updates = updates_;
  s.good_updates = updates_good_;
  s.solved_at = solved_at_;
  s.rng = rng_;
  s.countdown = countdown_;
  s.gap = gap_;
  return s;
}

bool JointInformation::load(const Saved& s) {
  const auto square = [this](const Eigen::MatrixXd& m) { return m.rows() == n_ && m.cols() == n_ && m.allFinite(); };
  if (!square(s.information) || !square(s.good_information) || s.countdown < 1 || s.gap < 1 ||
      s.solved_at > s.updates)
    return false;
  S_ = s.information;
  S_good_ = s.good_information;
  inv_w_.setOnes();
  inv_w_good_.setOnes();
  updates_ = s.updates;
  updates_good_ = s.good_updates;
  solved_at_ = s.solved_at;
  rng_ = s.rng;
  countdown_ = s.countdown;
  gap_ = s.gap;
  solved_ = current_ = false;  // until the next solve
  return true;
}

namespace {

// M = L^-1 in the lower triangle of a (n x n, column-major), A = L L^T the
// Cholesky factor of the symmetric a: A^-1 = M^T M. By hand: at these sizes
// Eigen's dynamic-size routines cost several times as much, and its solves
// with a matrix right-hand side allocate. False when A is not positive definite.
bool inverse_cholesky_factor(double* a, int n) {
  for (int j = 0; j < n; ++j) {  // L, column by column
    double d = a[j + j * n];
    for (int k = 0; k < j; ++k) d -= a[j + k * n] * a[j + k * n];
    if (!(d > 0.0)) return false;
    const double ljj = std::sqrt(d);
    a[j + j * n] = ljj;
    for (int i = j + 1; i < n; ++i) {
      double s = a[i + j * n];
      for (int k = 0; k < j; ++k) s -= a[i + k * n] * a[j + k * n];
      a[i + j * n] = s / ljj;
    }
  }
  for (int j = 0; j < n; ++j) {  // M = L^-1, column by column, in place
    a[j + j * n] = 1.0 / a[j + j * n];
    for (int i = j + 1; i < n; ++i) {
      double s = 0.0;
      for (int k = j; k < i; ++k) s -= a[i + k * n] * a[k + j * n];
      a[i + j * n] = s / a[i + i * n];
    }
  }
  return true;
}

// The diagonal block (o, o) of size nt of A^-1 = M^T M, M from inverse_cholesky_factor().
template <class Out>
void inverse_block(const double* M, int n, int o, int nt, Out& out) {
  for (int q = 0; q < nt; ++q)
    for (int p = 0; p <= q; ++p) {
      double s = 0.0;
      for (int k = o + q; k < n; ++k) s += M[k + (o + p) * n] * M[k + (o + q) * n];
      out(p, q) = out(q, p) = s;
    }
}

}  // namespace

void JointInformation::solve(std::vector<Block>& blocks, double noise_variance) {
  // J holds a memory of every block (its weight 1 - 1/e of its steady state).
  double memory = 0.0;
  for (const Block& b : blocks) memory = std::max(memory, 1.0 / std::max(1.0 - b.lambda_now, 1e-12));
  if (blocks.size() < 2 || static_cast<double>(updates_) < memory) return;  // C_i keep their values
  // J + R, R a prior per parameter that keeps J + R invertible where the data
  // leave a direction open: stabilisation x |theta_ref_j| (how far stabilised
  // forgetting lets an estimate wander there), else the covariance bound.
  for (int q = 0; q < n_; ++q)
    for (int r = 0; r < n_; ++r) A_(r, q) = S_(r, q) / (inv_w_(r) * inv_w_(q));
  for (std::size_t i = 0; i < blocks.size(); ++i) {
    const Block& b = blocks[i];
    for (int j = 0; j < b.nt; ++j) {
      const double prior = b.stabilisation_ratio * b.theta_ref(j);
      double info = prior != 0.0 && noise_variance > 0.0 ? noise_variance / (prior * prior) : 1.0 / b.p_limit(j);
      A_(offset_[i] + j, offset_[i] + j) += info;
      prior_(offset_[i] + j) = info;
    }
  }
  own_ = A_;  // A_ii, before A is factored in place
  if (!inverse_cholesky_factor(A_.data(), n_)) return;  // not positive definite: C_i keep their last values
  inverse_block(A_.data(), n_, 0, n_, inverse_);
  solved_ = inverse_.allFinite();
  bool current = solved_;
  for (std::size_t i = 0; i < blocks.size(); ++i) {
    Block& b = blocks[i];
    const int o = offset_[i], nt = b.nt;
    ThetaMat own(nt, nt), own_inv(nt, nt);
    const ThetaMat joint_inv = inverse_.block(o, o, nt, nt);
    // ((J + R)^-1 J (J + R)^-1)_ii, R diagonal.
    ThetaMat f(nt, nt);
    for (int q = 0; q < nt; ++q)
      for (int r = 0; r <= q; ++r) {
        double prior_part = 0.0;
        for (int k = 0; k < n_; ++k) prior_part += inverse_(o + r, k) * prior_(k) * inverse_(k, o + q);
        f(r, q) = f(q, r) = joint_inv(r, q) - prior_part;
      }
    b.sampling = f;
    current = current && f.allFinite();
    own = own_.block(o, o, nt, nt);
    if (!inverse_cholesky_factor(own.data(), nt)) continue;
    inverse_block(own.data(), nt, 0, nt, own_inv);
    ThetaMat c = joint_inv - own_inv;
    c = 0.5 * (c + c.transpose()).eval();
    if (c.allFinite())
      b.cross = c;
    else
      b.cross.setZero();
  }
  current_ = current;
}

}  // namespace modalwatch::detail
