// The daemon's checkpoint file: exact round trip, every corruption an
// InputError (truncation at every length, every flipped byte, wrong magic and
// version, absurd lengths, NaN), the config fingerprint, and an atomic write
// that leaves the previous checkpoint intact when writing fails.
#include <sys/mount.h>
#include <sys/resource.h>
#include <unistd.h>

#include <bit>
#include <cerrno>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <system_error>

#include <gtest/gtest.h>

#include "support.hpp"

#include "io/checkpoint/crc32.hpp"
#include "modalwatch/error.hpp"
#include "modalwatch/io/checkpoint.hpp"
#include "modalwatch/io/config.hpp"
#include "modalwatch/simulator.hpp"

namespace modalwatch {
namespace {

using test_support::error_of;
using test_support::ScratchDir;

Config paper_config() { return load_config(test_support::source_file("config/paper-sim.yaml")); }

// A real state: the paper's closed loop, 100 s, warmed up after 50 s.
Checkpoint real_checkpoint() {
  const Config c = paper_config();
  ExperimentSpec e = *c.experiment;
  e.duration = 100.0;
  const auto sim = simulate(*c.plant, e);
  RecursiveEstimator est(c.model, c.estimator);
  const Record& r = sim.record;
  for (Eigen::Index k = 0; k < r.size(); ++k) est.step({r.t(k), r.u(k), r.y(k), r.r(k)});
  Checkpoint cp;
  cp.config_fingerprint = checkpoint_fingerprint(c);
  cp.last_utime = 1'700'000'000'000'000 + 99'950'000;
  cp.last_seq = r.size() - 1;
  cp.estimator = est.state();
  ModeBaseline learned{{20.0, 0.1, 1.0}, {0.04, 1e-4, 2e-4, 1e-4, 1e-6, 3e-6, 2e-4, 3e-6, 1e-5}, true};
  ModeBaseline configured{{4.0, 0.05, 0.5}, {}, false};
  configured.covariance[4] = 2.5e-5;
  cp.baselines = {learned, std::nullopt, configured};
  return cp;
}

std::vector<std::uint8_t> read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void put_le(std::vector<std::uint8_t>& b, std::size_t at, std::uint64_t v, int n) {
  for (int i = 0; i < n; ++i) b[at + i] = static_cast<std::uint8_t>(v >> (8 * i));
}
// Recomputes the trailing CRC, so that the decoder gets past it to the field under test.
void reseal(std::vector<std::uint8_t>& b) { put_le(b, b.size() - 4, crc32(std::span(b).first(b.size() - 4)), 4); }

TEST(Checkpoint, Crc32IsTheStandardOne) {
  const std::string s = "123456789";
  EXPECT_EQ(crc32(std::span(reinterpret_cast<const std::uint8_t*>(s.data()), s.size())), 0xCBF43926u);
}

TEST(Checkpoint, RoundTripIsExact) {
  const Checkpoint cp = real_checkpoint();
  ASSERT_TRUE(cp.estimator.warmed_up());
  const auto bytes = encode_checkpoint(cp);
  const Checkpoint back = decode_checkpoint(bytes, "mem");
  EXPECT_EQ(encode_checkpoint(back), bytes);
  EXPECT_EQ(back.config_fingerprint, cp.config_fingerprint);
  EXPECT_EQ(back.last_utime, cp.last_utime);
  EXPECT_EQ(back.last_seq, cp.last_seq);
  ASSERT_EQ(back.estimator.model().submodels.size(), 3u);
  for (std::size_t i = 0; i < 3; ++i) {
    const auto& a = cp.estimator.model().submodels[i];
    const auto& b = back.estimator.model().submodels[i];
    EXPECT_EQ(a.name, b.name);
    EXPECT_EQ(a.a, b.a);  // bitwise
    EXPECT_EQ(a.b, b.b);
  }
  // Everything else the state holds (P, last good P, time scales, statistics), bit for bit.
  EXPECT_EQ(back.estimator, cp.estimator);
  EXPECT_EQ(back.estimator.last_sample_time(), cp.estimator.last_sample_time());
  EXPECT_EQ(back.estimator.status().updates, cp.estimator.status().updates);
  ASSERT_EQ(back.baselines.size(), 3u);
  EXPECT_FALSE(back.baselines[1].has_value());
  EXPECT_EQ(back.baselines[2]->value.zeta, 0.05);
  EXPECT_FALSE(back.baselines[2]->learned);
  EXPECT_EQ(back.baselines[2]->covariance[4], 2.5e-5);
  EXPECT_TRUE(back.baselines[0]->learned);
  EXPECT_EQ(back.baselines[0]->covariance, cp.baselines[0]->covariance);  // bitwise
  // And an estimator restored from the decoded state continues exactly like one
  // restored from the original.
  const Config c = paper_config();
  RecursiveEstimator e1(c.model, c.estimator), e2(c.model, c.estimator);
  e1.restore(cp.estimator);
  e2.restore(back.estimator);
  for (int k = 1; k <= 200; ++k) {
    const double t = cp.estimator.last_sample_time() + k * c.sample_time, u = std::sin(0.7 * t);
    e1.step({t, u, 0.5 * u, u});
    e2.step({t, u, 0.5 * u, u});
  }
  for (int i = 0; i < 3; ++i) EXPECT_EQ(e1.mode(i).value.wn, e2.mode(i).value.wn);
}

TEST(Checkpoint, EveryTruncationAndEveryFlippedByteIsAnInputError) {
  const auto bytes = encode_checkpoint(real_checkpoint());
  for (std::size_t n = 0; n < bytes.size(); ++n)
    EXPECT_THROW(decode_checkpoint(std::span(bytes).first(n), "cut"), InputError) << "length " << n;
  auto longer = bytes;
  longer.push_back(0);
  EXPECT_NE(error_of([&] { decode_checkpoint(longer, "long"); }).find("trailing"), std::string::npos);
  for (std::size_t i = 0; i < bytes.size(); ++i) {
    auto b = bytes;
    b[i] ^= 0x10;
    const std::string msg = error_of([&] { decode_checkpoint(b, "flip"); });
    if (i >= 20) {
      EXPECT_NE(msg.find("CRC-32 mismatch"), std::string::npos) << "byte " << i << ": " << msg;
    }
  }
  EXPECT_NE(error_of([&] { decode_checkpoint(std::span(bytes).first(100), "cut.ckpt"); }).find("cut.ckpt"),
            std::string::npos);
}

TEST(Checkpoint, WrongMagicVersionAndAbsurdLengthsAreNamed) {
  const auto good = encode_checkpoint(real_checkpoint());
  auto b = good;
  b[0] = 'X';
  EXPECT_NE(error_of([&] { decode_checkpoint(b, "m"); }).find("wrong magic"), std::string::npos);
  b = good;
  put_le(b, 8, kCheckpointVersion + 1, 4);
  EXPECT_NE(
      error_of([&] { decode_checkpoint(b, "v"); }).find("format version " + std::to_string(kCheckpointVersion + 1)),
      std::string::npos);
  b = good;
  put_le(b, 8, 1, 4);  // before the estimator state carried stabilised forgetting's reference
  EXPECT_NE(error_of([&] { decode_checkpoint(b, "v1"); }).find("format version 1 carries no stabilised-forgetting"),
            std::string::npos);
  b = good;
  put_le(b, 8, 2, 4);  // before it carried the instruments' joint information
  EXPECT_NE(error_of([&] { decode_checkpoint(b, "v2"); }).find("format version 2 carries no joint information"),
            std::string::npos);
  b = good;
  put_le(b, 8, 0, 4);
  EXPECT_NE(error_of([&] { decode_checkpoint(b, "v"); }).find("format version 0"), std::string::npos);
  b = good;
  put_le(b, 12, std::uint64_t{1} << 60, 8);
  EXPECT_NE(error_of([&] { decode_checkpoint(b, "l"); }).find("exceeds the limit"), std::string::npos);
  // Inside a payload with a valid CRC: counts beyond their caps, a length beyond
  // the bytes left, a NaN, an invalid boolean. Payload offsets: fingerprint 20,
  // utime 28, seq 36, warmed_up 44, submodel count 45, first name length 49.
  b = good;
  put_le(b, 45, 0xFFFFFFFFu, 4);
  reseal(b);
  EXPECT_NE(error_of([&] { decode_checkpoint(b, "k"); }).find("submodel count 4294967295 exceeds"), std::string::npos);
  b = good;
  put_le(b, 49, 0x7FFFFFFFu, 4);
  reseal(b);
  EXPECT_NE(error_of([&] { decode_checkpoint(b, "n"); }).find("byte offset 49"), std::string::npos);
  b = good;
  put_le(b, 49, 200, 4);  // under the cap, beyond what is left of a short payload
  b.resize(20 + 60);
  put_le(b, 12, 60, 8);
  b.resize(b.size() + 4);
  reseal(b);
  EXPECT_NE(error_of([&] { decode_checkpoint(b, "s"); }).find("truncated"), std::string::npos);
  b = good;
  b[44] = 7;
  reseal(b);
  EXPECT_NE(error_of([&] { decode_checkpoint(b, "f"); }).find("not a boolean"), std::string::npos);
  // The first coefficient a_1 of submodel 1 follows its name and three orders.
  b = good;
  const std::size_t a1 = 49 + 4 + real_checkpoint().estimator.model().submodels[0].name.size() + 12;
  put_le(b, a1, 0x7FF8000000000000ull, 8);
  reseal(b);
  EXPECT_NE(error_of([&] { decode_checkpoint(b, "nan"); }).find("not finite"), std::string::npos);
}

TEST(Checkpoint, FingerprintCoversStructureLoopAndForgettingButNotTheRest) {
  const Config c = paper_config();
  const std::uint64_t f = checkpoint_fingerprint(c);
  Config d = c;
  d.lcm.url = "memq://";
  d.model.submodels[0].a(1) *= 1.1;  // initial values
  d.estimator.outlier_sigma = 3.0;
  EXPECT_EQ(checkpoint_fingerprint(d), f);
  d = c;
  d.sample_time *= 2.0;
  EXPECT_NE(checkpoint_fingerprint(d), f);
  d = c;
  d.estimator.forgetting[1] = 0.99;
  EXPECT_NE(checkpoint_fingerprint(d), f);
  d = c;
  d.model.submodels[2].name = "other";
  EXPECT_NE(checkpoint_fingerprint(d), f);
  d = c;
  d.closed_loop = false;
  EXPECT_NE(checkpoint_fingerprint(d), f);
  d = c;
  d.controller = DiscreteTransferFunction({1.0, -0.5}, {1.0, -1.0});
  EXPECT_NE(checkpoint_fingerprint(d), f);
  d = c;
  d.model.submodels[0] = make_rigid_body(c.model.submodels[0].name, 1.0);
  EXPECT_NE(checkpoint_fingerprint(d), f);
}

TEST(Checkpoint, EncodeRefusesWhatDecodeWouldReject) {
  // The state of a new estimator (still warming up) on a model with one mode of that name.
  const auto state_named = [](std::size_t length) {
    EstimatorSettings s;
    s.sample_time = 0.01;
    s.warmup_samples = 10;
    return RecursiveEstimator(AdditiveModel{{make_mode(std::string(length, 'm'), {1.0, 0.1, 1.0})}, {}}, s).state();
  };
  Checkpoint cp;
  cp.estimator = state_named(257);
  EXPECT_THROW(encode_checkpoint(cp), std::invalid_argument);
  cp.estimator = state_named(256);
  EXPECT_EQ(decode_checkpoint(encode_checkpoint(cp), "m").estimator.model().submodels[0].name.size(), 256u);
  cp.baselines.resize(65);
  EXPECT_THROW(encode_checkpoint(cp), std::invalid_argument);
}

class CheckpointFile : public ScratchDir {};

TEST_F(CheckpointFile, WriteReadReplacesAtomically) {
  Checkpoint a = real_checkpoint(), b = a;
  b.last_seq += 100;
  const std::string p = path("axis.ckpt");
  write_checkpoint(p, a);
  EXPECT_EQ(read_bytes(p), encode_checkpoint(a));
  write_checkpoint(p, b);
  EXPECT_EQ(read_checkpoint(p).last_seq, b.last_seq);
  // Nothing but the checkpoint is left in the directory.
  const auto files = std::distance(std::filesystem::directory_iterator(dir_), std::filesystem::directory_iterator());
  EXPECT_EQ(files, 1);
  EXPECT_NE(error_of([&] { read_checkpoint(path("missing.ckpt")); }).find("missing.ckpt"), std::string::npos);
  write(path("garbage.ckpt"), "not a checkpoint at all");
  EXPECT_NE(error_of([&] { read_checkpoint(path("garbage.ckpt")); }).find("wrong magic"), std::string::npos);
}

TEST_F(CheckpointFile, AFailedWriteThrowsWithErrnoAndKeepsThePreviousCheckpoint) {
  const Checkpoint a = real_checkpoint();
  const std::string p = path("axis.ckpt");
  write_checkpoint(p, a);
  const auto before = read_bytes(p);
  Checkpoint big = a;
  big.baselines.resize(60, ModeBaseline{{1.0, 0.1, 1.0}, {}, true});
  // A file-size limit below the checkpoint's size: write() fails with EFBIG, as
  // it would with ENOSPC on a full disk. (As root, permissions stop nothing.)
  rlimit old{};
  ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &old), 0);
  auto* old_handler = std::signal(SIGXFSZ, SIG_IGN);
  rlimit small = old;
  small.rlim_cur = 512;
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &small), 0);
  int code = 0;
  try {
    write_checkpoint(p, big);
  } catch (const std::system_error& e) {
    code = e.code().value();
  }
  setrlimit(RLIMIT_FSIZE, &old);
  std::signal(SIGXFSZ, old_handler);
  EXPECT_EQ(code, EFBIG);
  EXPECT_EQ(read_bytes(p), before);
  const auto files = std::distance(std::filesystem::directory_iterator(dir_), std::filesystem::directory_iterator());
  EXPECT_EQ(files, 1) << "the temporary file was not removed";
  // A directory that does not exist.
  try {
    write_checkpoint(path("no/such/dir/axis.ckpt"), a);
    ADD_FAILURE() << "no exception";
  } catch (const std::system_error& e) {
    EXPECT_EQ(e.code().value(), ENOENT);
  }
}

TEST_F(CheckpointFile, FullFileSystemGivesEnospcAndKeepsThePreviousCheckpoint) {
  // A 64 KiB tmpfs, when this process may mount one (root with CAP_SYS_ADMIN).
  const std::string mnt = path("small");
  std::filesystem::create_directories(mnt);
  if (::mount("tmpfs", mnt.c_str(), "tmpfs", 0, "size=64k") != 0)
    GTEST_SKIP() << "cannot mount a tmpfs here (" << std::strerror(errno) << "): ENOSPC not reproduced";
  struct Unmount {
    std::string at;
    ~Unmount() { ::umount(at.c_str()); }
  } unmount{mnt};
  const Checkpoint a = real_checkpoint();
  const std::string p = mnt + "/axis.ckpt";
  write_checkpoint(p, a);
  const auto before = read_bytes(p);
  {  // fill the rest of the file system
    std::ofstream fill(mnt + "/fill", std::ios::binary);
    const std::string block(4096, 'x');
    for (int i = 0; i < 64 && fill.write(block.data(), block.size()); ++i) {
    }
  }
  int code = 0;
  try {
    write_checkpoint(p, a);
  } catch (const std::system_error& e) {
    code = e.code().value();
  }
  EXPECT_EQ(code, ENOSPC);
  EXPECT_EQ(read_bytes(p), before);
  std::filesystem::remove(mnt + "/fill");
  write_checkpoint(p, a);  // room again
  EXPECT_EQ(read_bytes(p), before);
}

}  // namespace
}  // namespace modalwatch
