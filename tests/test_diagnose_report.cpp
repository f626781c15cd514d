// modalwatch diagnose through its command and report: the plant effect keys of
// a config, simulate -> diagnose with the real binary (summary.json, report.md,
// stderr, the stop reason with its option, the measured frequency response in
// frf.csv), the report's JSON, and paths that need quoting.
#include <cmath>
#include <complex>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "../src/cli/json_writer.hpp"
#include "modalwatch/io/config.hpp"
#include "modalwatch/io/csv.hpp"
#include "modalwatch/model.hpp"
#include "support.hpp"

namespace modalwatch {
namespace {
// ------------------------------------------------------------ config and CLI

TEST(DiagnoseConfig, PlantEffectKeysAreReadAndChecked) {
  const std::string base = R"(sample_rate_hz: 100
model:
  submodels:
    - {name: m1, kind: mode, wn: 5, zeta: 0.05, gain: 1}
plant:
  coulomb: 0.3
  cubic: 0.02
  output_offset: 0.1
  input_offset: -0.2
  input_delay: 3
  modes:
    - {name: m1, kind: mode, wn: 5, zeta: 0.05, gain: 1}
)";
  const Config c = parse_config(base, "effects.yaml");
  ASSERT_TRUE(c.plant.has_value());
  EXPECT_EQ(c.plant->effects.coulomb, 0.3);
  EXPECT_EQ(c.plant->effects.cubic, 0.02);
  EXPECT_EQ(c.plant->effects.output_offset, 0.1);
  EXPECT_EQ(c.plant->effects.input_offset, -0.2);
  EXPECT_EQ(c.plant->effects.input_delay, 3);
  // Written back by config_to_yaml and read again.
  const Config again = parse_config(config_to_yaml(c, c.model), "again.yaml");
  EXPECT_EQ(again.plant->effects.input_delay, 3);
  EXPECT_EQ(again.plant->effects.coulomb, 0.3);
  auto replace = [&](const std::string& from, const std::string& to) {
    std::string t = base;
    t.replace(t.find(from), from.size(), to);
    return t;
  };
  std::string msg = test_support::error_of([&] { parse_config(replace("coulomb: 0.3", "coulomb: -1"), "e.yaml"); });
  EXPECT_NE(msg.find("e.yaml:6"), std::string::npos) << msg;
  EXPECT_NE(msg.find("plant.coulomb"), std::string::npos) << msg;
  msg = test_support::error_of([&] { parse_config(replace("input_delay: 3", "input_delay: 1.5"), "e.yaml"); });
  EXPECT_NE(msg.find("plant.input_delay"), std::string::npos) << msg;
  msg = test_support::error_of([&] { parse_config(replace("cubic: 0.02", "cubik: 0.02"), "e.yaml"); });
  EXPECT_NE(msg.find("unknown key"), std::string::npos) << msg;
}

class DiagnoseCli : public test_support::ScratchDir {};

// A 2-mode plant with an output offset its config's model does not declare.
constexpr const char* kOffsetPlant = R"(sample_rate_hz: 100
model:
  submodels:
    - {name: m1, kind: mode, wn: 5.3, zeta: 0.08, gain: 0.8}
    - {name: m2, kind: mode, wn: 19, zeta: 0.05, gain: 0.6}
plant:
  noise_variance: 1.0e-6
  output_offset: 0.2
  modes:
    - {name: m1, kind: mode, wn: 5, zeta: 0.05, gain: 1}
    - {name: m2, kind: mode, wn: 20, zeta: 0.03, gain: 0.5}
simulation:
  duration: 40
  input: {type: multisine, f_min_hz: 0.1, f_max_hz: 10, period_s: 10, rms: 1}
)";

// simulate -> diagnose through the real binary: the record carries an output
// offset the config does not declare; summary.json names it.
TEST_F(DiagnoseCli, FindsTheOffsetAndWritesTheReport) {
  const std::string config = write("plant.yaml", kOffsetPlant);
  auto out = test_support::run_cli("simulate --config " + config + " --out " + path("run.csv"));
  ASSERT_EQ(out.code, 0) << out.output;
  out = test_support::run_cli("diagnose --config " + config + " --data " + path("run.csv") +
                              " --split 0.7 --effects mode,offset,cubic --report " + path("report"));
  ASSERT_EQ(out.code, 0) << out.output;
  std::ifstream in(path("report/summary.json"));
  const std::string json((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(json.find("{\"effect\": \"none\", \"params\": {}"), std::string::npos) << json;
  const std::string key = "{\"effect\": \"offset\", \"params\": {\"value\": ";
  const auto at = json.find(key);
  ASSERT_NE(at, std::string::npos) << json;
  EXPECT_NEAR(std::stod(json.substr(at + key.size())), 0.2, 0.02) << json;
  EXPECT_TRUE(std::filesystem::exists(path("report/report.md")));
  EXPECT_TRUE(std::filesystem::exists(path("report/model.yaml")));
  // The augmented model is a config `fit` reads.
  out = test_support::run_cli("fit --config " + path("report/model.yaml") + " --data " + path("run.csv"));
  EXPECT_EQ(out.code, 0) << out.output;
  // Bad input is exit code 2 with the flag named.
  out = test_support::run_cli("diagnose --config " + config + " --data " + path("run.csv") +
                              " --effects mode,friction --report " + path("r2"));
  EXPECT_EQ(out.code, 2);
  EXPECT_NE(out.output.find("--effects"), std::string::npos) << out.output;
}

// The 2-mode plant of kOffsetPlant without the offset, in open loop or in
// closed loop with a PD controller and a multisine reference.
std::string two_mode_plant(bool closed) {
  const std::string excitation = closed ? "reference" : "input";
  return "sample_rate_hz: 100\nmodel:\n" + std::string(closed ? "  loop: closed\n" : "") +
         "  submodels:\n"
         "    - {name: m1, kind: mode, wn: 5.3, zeta: 0.08, gain: 0.8}\n"
         "    - {name: m2, kind: mode, wn: 19, zeta: 0.05, gain: 0.6}\n" +
         std::string(closed ? "controller:\n  numerator: [4.5, -4]\n  denominator: [1, 0]\n" : "") +
         "plant:\n"
         "  noise_variance: 1.0e-6\n"
         "  modes:\n"
         "    - {name: m1, kind: mode, wn: 5, zeta: 0.05, gain: 1}\n"
         "    - {name: m2, kind: mode, wn: 20, zeta: 0.03, gain: 0.5}\n"
         "simulation:\n"
         "  duration: 40\n  " +
         excitation + ": {type: multisine, f_min_hz: 0.1, f_max_hz: 10, period_s: 10, rms: 1}\n";
}

// frf.csv holds the measured frequency response of the estimation part: where
// the coherence is good it is the true plant's, in open loop (H1 = S_yu / S_uu)
// and in closed loop (S_yr / S_ur), beside the fitted model's.
TEST_F(DiagnoseCli, WritesTheMeasuredFrequencyResponseBesideTheModels) {
  AdditiveModel truth;
  truth.submodels = {make_mode("m1", {5.0, 0.05, 1.0}), make_mode("m2", {20.0, 0.03, 0.5})};
  for (const bool closed : {false, true}) {
    const std::string name = closed ? "closed" : "open";
    const std::string config = write(name + ".yaml", two_mode_plant(closed));
    auto out = test_support::run_cli("simulate --config " + config + " --out " + path(name + ".csv"));
    ASSERT_EQ(out.code, 0) << out.output;
    out = test_support::run_cli("diagnose --config " + config + " --data " + path(name + ".csv") +
                                " --split 0.7 --max-steps 0 --report " + path(name));
    ASSERT_EQ(out.code, 0) << out.output;
    const Table t = read_table(path(name + "/frf.csv"));
    ASSERT_EQ(t.columns, (std::vector<std::string>{"f_hz", "mag_measured", "phase_measured_deg", "coherence",
                                                   "mag_before", "phase_before_deg", "mag_after", "phase_after_deg"}));
    // Off the resonances (0.8 and 3.2 Hz), where 512-sample Hann windows leak
    // little: within 1.5 % and 3 degrees of the truth; the fitted model's columns within 0.1 %.
    for (const double hz : {2.0, 5.0, 8.0}) {
      Eigen::Index k = 0;
      (t.data.col(0).array() - hz).abs().minCoeff(&k);
      const double f = t.data(k, 0);
      EXPECT_NEAR(f, hz, 100.0 / 512) << name;
      const std::complex<double> g = truth.response(2.0 * std::numbers::pi * f);
      const double phase = std::arg(g) * 180.0 / std::numbers::pi;
      EXPECT_GT(t.data(k, 3), 0.99) << name << " " << f << " Hz";
      EXPECT_NEAR(t.data(k, 1), std::abs(g), 0.015 * std::abs(g)) << name << " " << f << " Hz";
      EXPECT_NEAR(t.data(k, 2), phase, 3.0) << name << " " << f << " Hz";
      EXPECT_NEAR(t.data(k, 4), std::abs(g), 1e-3 * std::abs(g)) << name << " " << f << " Hz";
      EXPECT_NEAR(t.data(k, 5), phase, 0.1) << name << " " << f << " Hz";
    }
  }
}

std::string read_text(const std::string& file) {
  std::ifstream in(file);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// The number after `key` on the line of `text` that contains `line`.
double number_after(const std::string& text, const std::string& line, const std::string& key) {
  const auto at = text.find(line);
  if (at == std::string::npos) return std::nan("");
  const auto k = text.find(key, at);
  if (k == std::string::npos || k > text.find('\n', at)) return std::nan("");
  return std::stod(text.substr(k + key.size()));
}

// A long run is not silent: one line per fit on stderr (the effect tried, its
// validation RMS, the time since the start); stdout keeps the report's table.
TEST_F(DiagnoseCli, PrintsEachFitOnStderr) {
  const std::string config = write("plant.yaml", kOffsetPlant);
  ASSERT_EQ(test_support::run_cli("simulate --config " + config + " --out " + path("run.csv")).code, 0);
  const std::string cmd = std::string(MODALWATCH_CLI) + " diagnose --config " + config + " --data " + path("run.csv") +
                          " --effects mode,offset,cubic --report " + path("report") + " >" + path("stdout.txt") +
                          " 2>" + path("stderr.txt");
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  const std::string err = read_text(path("stderr.txt")), out = read_text(path("stdout.txt"));
  // The configured model misses the 0.2 offset: its RMS is the offset's.
  EXPECT_NEAR(number_after(err, "step 0: configured model", "validation RMS "), 0.2, 0.01) << err;
  for (const char* effect : {"mode", "offset", "cubic"})
    EXPECT_NE(err.find(std::string("step 1/5: tried ") + effect + ": validation RMS "), std::string::npos)
        << effect << "\n" << err;
  // The offset takes the error down to the noise (std 1e-3).
  EXPECT_NEAR(number_after(err, "tried offset", "validation RMS "), 1e-3, 2e-4) << err;
  const double elapsed = number_after(err, "tried cubic", "(");
  EXPECT_GE(elapsed, 0.0) << err;
  EXPECT_LT(elapsed, 60.0) << err;
  EXPECT_EQ(out.find("tried"), std::string::npos) << out;
  EXPECT_NE(out.find("stopped:"), std::string::npos) << out;
}

// The report names the option whose rule stopped the run.
TEST_F(DiagnoseCli, StopReasonNamesTheOption) {
  const std::string config = write("plant.yaml", kOffsetPlant);
  ASSERT_EQ(test_support::run_cli("simulate --config " + config + " --out " + path("run.csv")).code, 0);
  const std::string data = " --config " + config + " --data " + path("run.csv");
  auto out = test_support::run_cli("diagnose" + data + " --max-steps 0 --report " + path("a"));
  ASSERT_EQ(out.code, 0) << out.output;
  EXPECT_NE(out.output.find("stopped: 0 effects added, the most allowed (--max-steps)"), std::string::npos)
      << out.output;
  EXPECT_NE(read_text(path("a/summary.json")).find("\"stop\": \"max_steps\""), std::string::npos);
  EXPECT_NE(read_text(path("a/report.md")).find("Stopped: 0 effects added, the most allowed (--max-steps)."),
            std::string::npos);
  out = test_support::run_cli("diagnose" + data + " --effects offset --min-improvement 0.999 --report " + path("b"));
  ASSERT_EQ(out.code, 0) << out.output;
  EXPECT_NE(out.output.find("less than the 99.9 % asked (--min-improvement)"), std::string::npos) << out.output;
  out = test_support::run_cli("diagnose" + data + " --effects mode --max-added-modes 0 --report " + path("c"));
  ASSERT_EQ(out.code, 0) << out.output;
  EXPECT_NE(out.output.find("stopped: 0 modes added, the most allowed, and no other effect to try (--max-added-modes)"),
            std::string::npos)
      << out.output;
  EXPECT_NE(read_text(path("c/summary.json")).find("\"stop\": \"mode_cap\""), std::string::npos);
}

// The report's JSON: strings escaped, numbers finite or null.
TEST(DiagnoseReportJson, EscapesStringsAndWritesNonFiniteAsNull) {
  using cli::json_string;
  EXPECT_EQ(json_string("plain"), "\"plain\"");
  EXPECT_EQ(json_string("a \"b\" c\\d"), "\"a \\\"b\\\" c\\\\d\"");
  EXPECT_EQ(json_string("l1\nl2\r\t\b\f"), "\"l1\\nl2\\r\\t\\b\\f\"");
  EXPECT_EQ(json_string(std::string("x\x01y\x1f", 4) + std::string(1, '\0')), "\"x\\u0001y\\u001f\\u0000\"");
  EXPECT_EQ(json_string("caf\xc3\xa9 \xe2\x82\xac"), "\"caf\xc3\xa9 \xe2\x82\xac\"");  // valid UTF-8 kept
  // Bytes that are not UTF-8 (a lone continuation, a truncated sequence, an
  // overlong form, a surrogate) become U+FFFD, one per byte.
  EXPECT_EQ(json_string("a\x80z"), "\"a\\ufffdz\"");
  EXPECT_EQ(json_string("\xe2\x82"), "\"\\ufffd\\ufffd\"");
  EXPECT_EQ(json_string("\xc0\xaf"), "\"\\ufffd\\ufffd\"");
  EXPECT_EQ(json_string("\xed\xa0\x80"), "\"\\ufffd\\ufffd\\ufffd\"");
  EXPECT_EQ(cli::json_number(0.25, 6), "0.25");
  EXPECT_EQ(cli::json_number(-1.5e-300, 3), "-1.5e-300");
  EXPECT_EQ(cli::json_number(std::nan(""), 6), "null");
  EXPECT_EQ(cli::json_number(-std::numeric_limits<double>::infinity(), 6), "null");

  cli::JsonWriter j;
  j.begin_object().key("k\"").value("v\n").key("list").begin_array(cli::JsonWriter::Layout::lines);
  j.value(1.0).begin_object().end_object().null().end_array();
  j.key("x").value(std::numeric_limits<double>::infinity()).key("b").value(true).end_object();
  EXPECT_EQ(j.finish(), "{\"k\\\"\": \"v\\n\", \"list\": [\n  1,\n  {},\n  null\n], \"x\": null, \"b\": true}\n");
  cli::JsonWriter bad;
  bad.begin_object();
  EXPECT_THROW(bad.value(1.0), std::logic_error);  // no key
  EXPECT_THROW(bad.end_array(), std::logic_error);
  EXPECT_THROW(bad.finish(), std::logic_error);  // still open
}

// Single-quoted for sh: the paths below hold quotes and newlines.
std::string sh_quote(const std::string& s) {
  std::string q = "'";
  for (const char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

// Paths with quotes, a tab and a newline: diagnose reads and writes there, the
// JSON of them parses back to them, and the plot script runs without a shell
// (its path is an argument, never parsed) with its exit status and stderr
// reported.
TEST_F(DiagnoseCli, ReportJsonAndPlotScriptWithQuotesAndNewlinesInPaths) {
  if (!std::filesystem::exists("/usr/bin/python3")) GTEST_SKIP() << "no /usr/bin/python3 to run the scripts";
  const std::string dir = path("it's a \"dir\"\nhere");
  std::filesystem::create_directories(dir);
  const std::string config = dir + "/plant \"q\".yaml";
  std::ofstream(config) << R"(sample_rate_hz: 100
model:
  submodels:
    - {name: m1, kind: mode, wn: 5.3, zeta: 0.08, gain: 0.8}
plant:
  noise_variance: 1.0e-6
  modes:
    - {name: m1, kind: mode, wn: 5, zeta: 0.05, gain: 1}
simulation:
  duration: 20
  input: {type: multisine, f_min_hz: 0.1, f_max_hz: 10, period_s: 10, rms: 1}
)";
  const std::string data = dir + "/run\t1.csv";
  auto out = test_support::run_cli("simulate --config " + sh_quote(config) + " --out " + sh_quote(data));
  ASSERT_EQ(out.code, 0) << out.output;
  const std::string script = dir + "/plot's \"fail\".py";
  std::ofstream(script) << "import sys\nsys.stderr.write('no \"plots\" here\\n')\nsys.exit(3)\n";
  const std::string report = dir + "/report";
  out = test_support::run_cli("diagnose --config " + sh_quote(config) + " --data " + sh_quote(data) +
                              " --split 0.7 --effects offset --max-steps 0 --report " + sh_quote(report) +
                              " --plot-script " + sh_quote(script));
  ASSERT_EQ(out.code, 0) << out.output;
  EXPECT_NE(out.output.find("no \"plots\" here"), std::string::npos) << out.output;
  EXPECT_NE(out.output.find("plots failed (/usr/bin/python3 " + script + " exited with status 3)"), std::string::npos)
      << out.output;
  std::ifstream md(report + "/report.md");
  const std::string report_md((std::istreambuf_iterator<char>(md)), std::istreambuf_iterator<char>());
  EXPECT_NE(report_md.find("Not made (/usr/bin/python3 " + script + " exited with status 3)"), std::string::npos);

  // Parsed back by Python's json: summary.json, and a document holding the paths.
  cli::JsonWriter doc;
  doc.begin_object().key("config").value(config).key("data").value(data).key("report").value(report).end_object();
  const std::string paths = write("paths.json", doc.finish());
  const std::string checker = write("check.py", R"(import json, sys
s = json.load(open(sys.argv[1], encoding="utf-8"))
assert s["steps"][0]["effect"] == "none" and s["steps"][0]["submodels"][0]["name"] == "m1"
d = json.load(open(sys.argv[2], encoding="utf-8"))
open(sys.argv[3], "wb").write((d["config"] + "\0" + d["data"] + "\0" + d["report"]).encode("utf-8"))
)");
  ASSERT_EQ(std::system(("/usr/bin/python3 " + checker + " " + sh_quote(report + "/summary.json") + " " + paths + " " +
                         path("parsed.bin"))
                            .c_str()),
            0);
  std::ifstream parsed(path("parsed.bin"), std::ios::binary);
  const std::string nul(1, '\0');
  EXPECT_EQ(std::string((std::istreambuf_iterator<char>(parsed)), std::istreambuf_iterator<char>()),
            config + nul + data + nul + report);
}

}  // namespace
}  // namespace modalwatch
