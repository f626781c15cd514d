#pragma once
// The instruments' information across blocks, for the covariance the
// estimator reports. Each block's P_i is its own recursion's (eqs. 23-25):
// the inverse of its information with the other blocks' parameters taken as
// known, since eq. (15) subtracts their outputs. Where blocks' instruments
// share a direction (a setpoint of a few sines, close modes) the data tell
// their parameters apart far less well than P_i says: a mode can trade part
// of its gain and damping against a neighbour's with no change of the output
// error, and a test of that mode against sigma^2 P_i alone takes the trade for
// a change of the mode.
//
// J = sum_s lambda^(t-s) psi_s psi_s^T, psi the blocks' instruments stacked,
// is the information of the whole theta (eq. 8's covariance over the
// recursion's memory; block pair (i, j) forgets by sqrt(lambda_i lambda_j)).
// With R a prior that keeps J + R invertible where the data leave a direction
// open (stabilisation x |theta_ref_j| per parameter: how far stabilised
// forgetting lets an estimate wander there), what not knowing the others adds
// to block i's covariance is the Schur complement's difference
//   C_i = ((J + R)^-1)_ii - ((J + R)_ii)^-1,
// positive semi-definite. The estimator reports sigma^2 (P_i + C_i). A test
// for a change takes the estimate's sampling covariance instead, without R's
// share: ((J + R)^-1 J (J + R)^-1)_ii = ((J + R)^-1 - (J + R)^-1 R (J + R)^-1)_ii. P_i
// itself never takes C_i: the recursion must stay block-coordinate, or each
// block answers for its neighbours' share too and the two run apart along the
// shared direction (warmup_fit.cpp).
//
// Kept as J = W S W with W diagonal, so that forgetting costs one product per
// parameter instead of one per entry of J: W <- sqrt(lambda)^g W over g
// updates, and S <- S + g (W^-1 psi)(W^-1 psi)^T. The instruments enter every
// g-th update only, g drawn in [1, 2 stride - 1] with about 64 of them per
// shortest memory (a fixed g would alias lines of psi psi^T at multiples of
// 2 pi / g onto their mean), each with weight g: J is the same sum sampled, at
// a small part of the cost. C_i is solved every kSolveEvery updates, once J
// holds a memory of the longest-memory block. A change boost empties J: across
// a change it would mix instruments of the model before and after, a richness
// the data do not have; C_i keep their values until J holds a memory again
// (zero after the warm-up).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "block.hpp"
#include "hot_path.hpp"

namespace modalwatch::detail {

class JointInformation {
 public:
  static constexpr int kSolveEvery = 256;  // updates

  // Sized for these blocks (allocates); J empty.
  void resize(const std::vector<Block>& blocks);
  // J empty (the blocks' C_i keep their values until J holds a memory again).
  void clear();

  // Per update, after every block's (Block::psi, Block::lambda_now): J's
  // forgetting, and every few updates the instruments. True when C_i are due
  // to be solved for.
  MODALWATCH_HOT bool update(const std::vector<Block>& blocks) {
    ++updates_;
    if (--countdown_ > 0) return false;
    accumulate(blocks);
    if (updates_ - solved_at_ < kSolveEvery) return false;
    solved_at_ = updates_;
    return true;
  }
  // C_i into Block::cross of every block, once J holds a memory of each.
  void solve(std::vector<Block>& blocks, double noise_variance);
  // (J + R)^-1 of the last solve (normalised theta, blocks at offset()), whose
  // block (i, j) is the covariance of theta_i with theta_j over sigma^2;
  // solved() is false before the first solve and after a load.
  bool solved() const { return solved_; }
  const Eigen::MatrixXd& inverse() const { return inverse_; }
  // True from a solve until J is emptied or returned to the last good state:
  // only then do the blocks' P_i stand where J says, and Block::sampling hold
  // the estimate's sampling covariance.
  bool current() const { return current_; }
  int offset(std::size_t block) const { return offset_[block]; }

  // Returned to with the estimator's last good state.
  void save_good();
  void restore_good();

  // What a checkpoint carries (EstimatorState): J now and at the last good
  // state, and where the sampling stands.
  struct Saved {
    Eigen::MatrixXd information, good_information;
    std::uint64_t updates = 0, good_updates = 0, solved_at = 0, rng = 0;
    std::int32_t countdown = 1, gap = 1;
  };
  Saved saved() const;
  // False (and nothing changed) for a state of another size or with values out of range.
  bool load(const Saved& s);

 private:
  MODALWATCH_HOT void accumulate(const std::vector<Block>& blocks);
  void rescale_weights();

  int n_ = 0;                // sum of nt
  std::vector<int> offset_;  // per block, where its parameters start
  Eigen::MatrixXd S_;        // J = W S W
  Eigen::VectorXd inv_w_, v_;
  std::uint64_t updates_ = 0, solved_at_ = 0;
  int countdown_ = 1, gap_ = 1;  // updates to the next accumulation, and since the last
  std::uint64_t rng_ = 0x9e3779b97f4a7c15ULL;
  Eigen::MatrixXd S_good_;
  Eigen::VectorXd inv_w_good_;
  std::uint64_t updates_good_ = 0;
  // The solve's workspace (no allocation once sized), and its result.
  Eigen::MatrixXd A_, own_, inverse_;
  Eigen::VectorXd prior_;  // R's diagonal
  bool solved_ = false, current_ = false;
};

MODALWATCH_HOT void JointInformation::accumulate(const std::vector<Block>& blocks) {
  constexpr double kPerMemory = 64.0;  // accumulations per shortest memory
  constexpr double kRescaleAbove = 1e100;
  const double sqrt_gap = std::sqrt(static_cast<double>(gap_));
  double* __restrict iw = inv_w_.data();
  double* __restrict v = v_.data();
  bool rescale = false;
  double shortest = 1e300;  // memory, updates
  std::size_t p = 0;
  for (std::size_t i = 0; i < blocks.size(); ++i) {
    const Block& b = blocks[i];
    // J's forgetting over the gap, lambda^(-gap/2) (lambda varies little over a few updates).
    const double root = 1.0 / std::sqrt(b.lambda_now);
    double grow = 1.0, power = root;
    for (int g = gap_; g > 0; g >>= 1, power *= power)
      if (g & 1) grow *= power;
    for (int j = 0; j < b.nt; ++j, ++p) {
      iw[p] *= grow;
      v[p] = sqrt_gap * b.psi(j) * iw[p];
    }
    rescale |= iw[p - 1] > kRescaleAbove;
    shortest = std::min(shortest, 1.0 / std::max(1.0 - b.lambda_now, 1e-12));
  }
  // All of S (J's lower half is not needed, but full columns vectorise).
  const auto n = static_cast<std::size_t>(n_);
  double* __restrict S = S_.data();
  for (std::size_t q = 0; q < n; ++q) {
    const double vq = v[q];
    double* __restrict column = S + q * n;
    for (std::size_t r = 0; r < n; ++r) column[r] += v[r] * vq;
  }
  if (rescale) rescale_weights();
  const double stride = std::clamp(std::round(shortest / kPerMemory), 1.0, 32.0);
  rng_ = rng_ * 6364136223846793005ULL + 1442695040888963407ULL;  // Knuth's MMIX LCG
  const auto span = static_cast<std::uint64_t>(2.0 * stride - 1.0);
  gap_ = countdown_ = static_cast<int>(1 + (rng_ >> 33) % span);
}

}  // namespace modalwatch::detail
