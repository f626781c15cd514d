// Every command that reads a record takes an LCM log as it takes the CSV
// (fit, track, diagnose, simulate's excitation, several inputs), and
// `modalwatch replay` over real UDP multicast (udpm on the loopback, ttl=0),
// received here with liblcm's C API.
#include <lcm/lcm.h>

#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "lcm_log_support.hpp"
#include "simulation_support.hpp"
#include "support.hpp"

#include "modalwatch/estimator.hpp"
#include "modalwatch/io/config.hpp"
#include "modalwatch/io/csv.hpp"
#include "modalwatch/io/lcm_log.hpp"
#include "modalwatch/io/messages.hpp"
#include "modalwatch/io/records.hpp"
#include "modalwatch/simulator.hpp"

namespace modalwatch {
namespace {

using test_support::kConfig;
using test_support::kStart;
using test_support::LcmLog;
using test_support::run_cli;

// A group and port of this test process's own, so that other LCM traffic on
// the machine (a daemon, another test run on the default URL) cannot interfere.
std::string test_url() {
  return "udpm://239.255.76." + std::to_string(100 + ::getpid() % 100) + ":" + std::to_string(7700 + ::getpid() % 200) +
         "?ttl=0";
}

TEST_F(LcmLog, FitTrackAndDiagnoseReadLogsExactlyAsTheyReadCsv) {
  const Record csv = csv_record(path("run.csv"));
  write_log(path("run.lcm"), csv, "MODALWATCH_SAMPLES", 1);
  const auto fit_csv = run_cli("fit -c " + kConfig + " -d " + path("run.csv"));
  const auto fit_lcm = run_cli("fit -c " + kConfig + " -d " + path("run.lcm") + " --channel MODALWATCH_SAMPLES");
  ASSERT_EQ(fit_csv.code, 0) << fit_csv.output;
  ASSERT_EQ(fit_lcm.code, 0) << fit_lcm.output;
  EXPECT_NE(fit_lcm.output.find("2000 samples from LCM log"), std::string::npos) << fit_lcm.output;
  // The modal table (everything after the reader's line) is the same.
  const auto table = [](const std::string& s) { return s.substr(s.find("modalwatch fit:")); };
  EXPECT_EQ(table(fit_lcm.output), table(fit_csv.output));
  // Two channels with samples and no --channel: the user has to choose.
  const auto ambiguous = run_cli("fit -c " + kConfig + " -d " + path("run.lcm"));
  EXPECT_EQ(ambiguous.code, 2);
  EXPECT_NE(ambiguous.output.find("choose one with --channel"), std::string::npos) << ambiguous.output;
  const auto wrong = run_cli("fit -c " + kConfig + " -d " + path("run.lcm") + " --channel NOPE");
  EXPECT_EQ(wrong.code, 2);
  EXPECT_NE(wrong.output.find("on channel 'NOPE'"), std::string::npos) << wrong.output;

  ASSERT_EQ(run_cli("track --no-progress -c " + kConfig + " -d " + path("run.csv") + " -o " + path("a.csv")).code, 0);
  const auto tr = run_cli("track --no-progress -c " + kConfig + " -d " + path("run.lcm") +
                          " --channel MODALWATCH_SAMPLES -o " + path("b.csv"));
  ASSERT_EQ(tr.code, 0) << tr.output;
  const Table a = read_table(path("a.csv")), b = read_table(path("b.csv"));
  ASSERT_EQ(a.data.rows(), b.data.rows());
  // Same samples, same estimates; only t carries the 1 us utime rounding.
  EXPECT_EQ(a.data.rightCols(a.data.cols() - 1), b.data.rightCols(b.data.cols() - 1));

  // diagnose reads logs too: the same steps (summary.json) from either record.
  const std::string diag = "diagnose -c " + kConfig + " --split 0.7 --effects offset --max-steps 1";
  const auto d_csv = run_cli(diag + " -d " + path("run.csv") + " -r " + path("d_csv"));
  const auto d_lcm = run_cli(diag + " -d " + path("run.lcm") + " --channel MODALWATCH_SAMPLES -r " + path("d_lcm"));
  ASSERT_EQ(d_csv.code, 0) << d_csv.output;
  ASSERT_EQ(d_lcm.code, 0) << d_lcm.output;
  const auto slurp = [](const std::string& p) {
    std::ifstream in(p);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  const std::string summary = slurp(path("d_csv/summary.json"));
  EXPECT_NE(summary.find("\"validation_rms\""), std::string::npos) << summary;
  EXPECT_EQ(slurp(path("d_lcm/summary.json")), summary);
}

// A config's signal file (`type: csv` under simulation.reference) may be an LCM
// log too: `simulate` driven by the reference recorded in a log gives the run it
// gives from the same record as CSV; the log's two sample channels need the
// key `channel`, and the library's own loader (no LCM) refuses that key.
TEST_F(LcmLog, SimulateReadsItsExcitationFromALogAsFromCsv) {
  const Record rec = csv_record(path("run.csv"));
  write_log(path("run.lcm"), rec, "MODALWATCH_SAMPLES", 1);
  std::ifstream in(kConfig);
  std::string yaml(std::istreambuf_iterator<char>(in), {});
  const std::string from =
      "    type: sum_of_sines\n    amplitudes: [3, 1, 1, 1]\n    frequencies_rad_s: [0.005, 2, 5, 17.5]\n";
  ASSERT_NE(yaml.find(from), std::string::npos);
  const auto config_with = [&](const std::string& name, const std::string& reference) {
    std::string text = yaml;
    text.replace(text.find(from), from.size(), reference);
    text.replace(text.find("duration: 1000"), 14, "duration: 99");  // within the 100 s record
    std::ofstream(path(name)) << text;
    return path(name);
  };
  const std::string from_csv = config_with("csv.yaml", "    type: csv\n    path: run.csv\n    column: r\n");
  const std::string from_log =
      config_with("log.yaml", "    type: csv\n    path: run.lcm\n    column: r\n    channel: MODALWATCH_SAMPLES\n");
  const auto a = run_cli("simulate -c " + from_csv + " -o " + path("a.csv"));
  const auto b = run_cli("simulate -c " + from_log + " -o " + path("b.csv"));
  ASSERT_EQ(a.code, 0) << a.output;
  ASSERT_EQ(b.code, 0) << b.output;
  EXPECT_NE(b.output.find("2000 samples from LCM log"), std::string::npos) << b.output;
  const Table ta = read_table(path("a.csv")), tb = read_table(path("b.csv"));
  ASSERT_EQ(ta.columns, tb.columns);
  ASSERT_EQ(ta.data.rows(), 1980);
  // The log's t is the CSV's rounded to 1 us, which moves the interpolation
  // weights by round-off only.
  EXPECT_LT((ta.data - tb.data).cwiseAbs().maxCoeff(), 1e-9);
  // ... and the reference on the grid is the recorded one.
  const int r = tb.column("r");
  ASSERT_GE(r, 0);
  EXPECT_LT((tb.data.col(r) - rec.r.head(1980)).cwiseAbs().maxCoeff(), 1e-12);

  const std::string no_channel = config_with("nochannel.yaml", "    type: csv\n    path: run.lcm\n    column: r\n");
  const auto ambiguous = run_cli("simulate -c " + no_channel + " -o " + path("c.csv"));
  EXPECT_EQ(ambiguous.code, 2);
  EXPECT_NE(ambiguous.output.find("key 'simulation.reference.path'"), std::string::npos) << ambiguous.output;
  EXPECT_NE(ambiguous.output.find("choose one"), std::string::npos) << ambiguous.output;
  const auto no_column = run_cli("simulate -c " +
                                 config_with("q.yaml",
                                             "    type: csv\n    path: run.lcm\n"
                                             "    column: q\n    channel: MODALWATCH_SAMPLES\n") +
                                 " -o " + path("c.csv"));
  EXPECT_EQ(no_column.code, 2);
  EXPECT_NE(no_column.output.find("no such column"), std::string::npos) << no_column.output;

  // load_config reads the log itself: the excitation is the CSV's, to round-off.
  const Config config_log = load_config(from_log), config_csv = load_config(from_csv);
  ASSERT_TRUE(config_log.experiment && config_csv.experiment);
  const Eigen::VectorXd& x_log = config_log.experiment->excitation_samples;
  const Eigen::VectorXd& x_csv = config_csv.experiment->excitation_samples;
  ASSERT_EQ(x_log.size(), x_csv.size());
  EXPECT_LT((x_log - x_csv).cwiseAbs().maxCoeff(), 1e-9);
}

// ------------------------------------------------------------------ replay

struct Received {
  std::vector<StampedSample> samples;
  std::uint64_t packets = 0, bad = 0;
  int inputs = 1;  // the model's, as the daemon decodes
  std::int64_t fingerprint = 0;  // of the last packet
};

void on_message(const lcm_recv_buf_t* rbuf, const char*, void* user) {
  auto* r = static_cast<Received*>(user);
  StampedSample buf[256];
  int n = 0;
  if (rbuf->data_size >= 8) {
    std::uint64_t f = 0;
    for (int i = 0; i < 8; ++i) f = f << 8 | static_cast<const std::uint8_t*>(rbuf->data)[i];
    r->fingerprint = static_cast<std::int64_t>(f);
  }
  if (decode_samples(rbuf->data, static_cast<int>(rbuf->data_size), true, buf, 256, n, r->inputs) !=
      DecodeResult::ok) {
    ++r->bad;
    return;
  }
  ++r->packets;
  r->samples.insert(r->samples.end(), buf, buf + n);
}

// Receives on `url` while `modalwatch replay <args>` runs; returns its outcome.
test_support::Outcome replay_into(const std::string& url, const std::string& channel, const std::string& args,
                                  Received& got, bool& lcm_ok) {
  lcm_t* lcm = lcm_create(url.c_str());
  lcm_ok = lcm != nullptr;
  if (!lcm) return {-1, ""};
  lcm_subscription_t* sub = lcm_subscribe(lcm, channel.c_str(), on_message, &got);
  // LCM keeps 30 messages per subscription by default and drops the rest
  // silently: a handler thread stalled by a loaded machine would lose samples.
  if (sub) lcm_subscription_set_queue_capacity(sub, 100000);
  std::atomic<bool> done{false};
  test_support::Outcome out;
  std::thread child([&] {
    out = run_cli("replay " + args + " --url '" + url + "'");
    done = true;
  });
  auto drain_until = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  while (std::chrono::steady_clock::now() < drain_until) {
    if (lcm_handle_timeout(lcm, 100) == 0 && done) break;  // quiet for 100 ms after the replay ended
  }
  child.join();
  lcm_unsubscribe(lcm, sub);
  lcm_destroy(lcm);
  return out;
}

TEST_F(LcmLog, ReplayPublishesEverySampleExactlyOverUdpMulticast) {
  const Record csv = csv_record(path("run.csv"));
  const std::string url = test_url();
  for (int batch : {1, 50}) {
    Received got;
    bool lcm_ok = false;
    const std::string channel = batch == 1 ? "MODALWATCH_SAMPLES" : "MODALWATCH_BATCHES";
    // 100 s of record at 50 x real time: 2 s, 1000 packets/s at most.
    const auto out = replay_into(url, channel,
                                 "-c " + kConfig + " -d " + path("run.csv") + " --speed 50 --batch " +
                                     std::to_string(batch) + " --start-utime " + std::to_string(kStart),
                                 got, lcm_ok);
    if (!lcm_ok) GTEST_SKIP() << "LCM cannot open " << url << " (no multicast route? see scripts/setup.sh)";
    ASSERT_EQ(out.code, 0) << out.output;
    EXPECT_NE(out.output.find("2000 samples in " + std::to_string((2000 + batch - 1) / batch)), std::string::npos)
        << out.output;
    EXPECT_EQ(got.bad, 0u);
    ASSERT_EQ(got.samples.size(), 2000u) << "batch " << batch << ": " << got.packets << " packets received";
    for (std::size_t k = 0; k < got.samples.size(); ++k) {
      const StampedSample& s = got.samples[k];
      ASSERT_EQ(s.seq, static_cast<std::int64_t>(k));
      ASSERT_EQ(s.utime, kStart + static_cast<std::int64_t>(k) * 50000) << k;
      ASSERT_EQ(s.u, csv.u(static_cast<Eigen::Index>(k))) << k;
      ASSERT_EQ(s.y, csv.y(static_cast<Eigen::Index>(k))) << k;
      ASSERT_EQ(s.r, csv.r(static_cast<Eigen::Index>(k))) << k;
    }
  }
}

// ------------------------------------------------------------------ several inputs

// A two-input record (the paper's open-loop plant with its mode2 on a second
// input, white noise) and a config of that model naming the inputs u1, u2.
class TwoInputLog : public LcmLog {
 protected:
  std::string two_input_config() {
    return write("two.yaml",
                 "sample_rate_hz: 20\n"
                 "model:\n"
                 "  inputs: [u1, u2]\n"
                 "  submodels:\n"
                 "    - {name: mode1, wn: 2.0, zeta: 0.25, gain: 3.0, forgetting: 0.999}\n"
                 "    - {name: mode2, input: u2, wn: 5.0, zeta: 0.025, gain: 0.5, forgetting: 0.999}\n"
                 "    - {name: mode3, wn: 20.0, zeta: 0.1, gain: 1.0, forgetting: 0.999}\n"
                 "estimator:\n"
                 "  warmup: 50\n");
  }
  Record two_input_record() {
    const Config c = load_config(kConfig);
    PlantSpec plant = *c.plant;
    plant.modes[1].submodel.input = 1;
    ExperimentSpec e = *c.experiment;
    e.duration = 200.0;
    e.closed_loop = false;
    e.further_input_samples = {modalwatch::test_support::white_noise(4000, 5)};
    return simulate(plant, e).record;
  }
  // The record as sample_batch2_t events on IN, 64 samples a batch.
  void write_two_input_log(const std::string& path, const Record& rec) {
    lcm_t* lcm = lcm_create(("file://" + path + "?mode=w").c_str());
    ASSERT_NE(lcm, nullptr);
    for (Eigen::Index k = 0; k < rec.size(); k += 64) {
      const auto msg = encode_batch(rec, k, std::min<Eigen::Index>(64, rec.size() - k), kStart);
      EXPECT_EQ(lcm_publish(lcm, "IN", msg.data(), static_cast<unsigned>(msg.size())), 0);
    }
    lcm_destroy(lcm);
  }
};

// track reads a log's sample_batch2_t inputs in the model's order: its
// estimates are the recursive estimator's on the record read back from the
// log; a log of another number of inputs is named as such.
TEST_F(TwoInputLog, TrackReadsTheInputsOfALogInTheModelsOrder) {
  const Record rec = two_input_record();
  write_two_input_log(path("two.lcm"), rec);
  const std::string cfg = two_input_config();
  const auto tr = run_cli("track --no-progress -c " + cfg + " -d " + path("two.lcm") + " -o " + path("est.csv"));
  ASSERT_EQ(tr.code, 0) << tr.output;
  EXPECT_NE(tr.output.find("4000 samples from LCM log"), std::string::npos) << tr.output;
  const Config c = load_config(cfg);
  RecordColumns columns;
  columns.u = "u1";
  columns.further_u = {"u2"};
  RecordReadOptions options;
  options.allow_gaps = true;
  options.sample_time = c.sample_time;
  const Record back = read_record(RecordSource(path("two.lcm"), columns), options);
  ASSERT_EQ(back.inputs(), 2);
  EXPECT_EQ(back.further_u[0], rec.further_u[0]);
  RecursiveEstimator est(c.model, c.estimator);
  Sample s;
  s.further_inputs = 1;
  for (Eigen::Index k = 0; k < back.size(); ++k) {
    s.t = back.t(k);
    s.u = back.u(k);
    s.y = back.y(k);
    s.further_u[0] = back.further_u[0](k);
    est.step(s);
  }
  const Table t = read_table(path("est.csv"));
  ASSERT_EQ(t.data.rows(), back.size());
  for (int i = 0; i < 3; ++i) {
    const std::string name = "mode" + std::to_string(i + 1);
    EXPECT_EQ(t.data(back.size() - 1, t.column(name + "_wn")), est.mode(i).value.wn) << name;
  }
  // The paper's modes, mode2 followed on u2.
  EXPECT_NEAR(est.mode(1).value.wn, 5.0, 0.05);
  // A single-input config on the two-input log: no sample of one input in it.
  const auto one = run_cli("track --no-progress -c " + kConfig + " -d " + path("two.lcm") + " -o " + path("one.csv"));
  EXPECT_EQ(one.code, 2) << one.output;
  EXPECT_NE(one.output.find("of another number of inputs"), std::string::npos) << one.output;
}

// replay sends a two-input record as sample2_t (one per packet) or
// sample_batch2_t (batches), every input of every sample, over UDP multicast.
TEST_F(TwoInputLog, ReplaySendsEveryInputAsSample2AndBatch2) {
  const std::string cfg = two_input_config();
  for (int batch : {1, 50}) {
    // One packet per sample: 20 s of record at 20 x real time (400 packets/s,
    // which a loaded machine's socket buffer keeps); batches: 100 s at 50 x.
    const Record rec = two_input_record().segment(0, batch == 1 ? 400 : 2000);
    Eigen::MatrixXd table(rec.size(), 4);
    table << rec.t, rec.u, rec.further_u[0], rec.y;
    write_table(path("two.csv"), {"t", "u1", "u2", "y"}, table);
    Received got;
    got.inputs = 2;
    bool lcm_ok = false;
    const std::string channel = batch == 1 ? "MODALWATCH_SAMPLES" : "MODALWATCH_BATCHES";
    const auto out = replay_into(test_url(), channel,
                                 "-c " + cfg + " -d " + path("two.csv") + " --speed " + (batch == 1 ? "20" : "50") +
                                     " --batch " + std::to_string(batch) + " --start-utime " + std::to_string(kStart),
                                 got, lcm_ok);
    if (!lcm_ok) GTEST_SKIP() << "no multicast";
    ASSERT_EQ(out.code, 0) << out.output;
    EXPECT_NE(out.output.find(batch == 1 ? "sample2_t packets" : "sample_batch2_t packets"), std::string::npos)
        << out.output;
    EXPECT_EQ(got.fingerprint, batch == 1 ? sample2_fingerprint() : batch2_fingerprint());
    EXPECT_EQ(got.bad, 0u);
    ASSERT_EQ(got.samples.size(), static_cast<std::size_t>(rec.size())) << "batch " << batch;
    for (std::size_t k = 0; k < got.samples.size(); ++k) {
      const auto i = static_cast<Eigen::Index>(k);
      ASSERT_EQ(got.samples[k].seq, static_cast<std::int64_t>(k));
      ASSERT_EQ(got.samples[k].u, rec.u(i)) << k;
      ASSERT_EQ(got.samples[k].further_inputs, 1) << k;
      ASSERT_EQ(got.samples[k].further_u[0], rec.further_u[0](i)) << k;
      ASSERT_EQ(got.samples[k].y, rec.y(i)) << k;
    }
  }
}

TEST_F(LcmLog, ReplayPacesAtTheRequestedSpeedAndReadsLogs) {
  const Record csv = csv_record(path("run.csv"));
  write_log(path("run.lcm"), csv.segment(0, 201), "IN", 1);  // 10 s of record
  Received got;
  bool lcm_ok = false;
  const auto t0 = std::chrono::steady_clock::now();
  const auto out = replay_into(test_url(), "MODALWATCH_SAMPLES",
                               "-c " + kConfig + " -d " + path("run.lcm") + " --channel IN --speed 10", got, lcm_ok);
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (!lcm_ok) GTEST_SKIP() << "no multicast";
  ASSERT_EQ(out.code, 0) << out.output;
  EXPECT_EQ(got.samples.size(), 201u);
  // 10 s at 10 x: 1 s, plus process start and the 100 ms drain.
  EXPECT_GT(wall, 0.95);
  EXPECT_LT(wall, 3.0);
  EXPECT_EQ(run_cli("replay -c " + kConfig + " -d " + path("run.csv") + " --speed fast").code, 2);
}

}  // namespace
}  // namespace modalwatch
