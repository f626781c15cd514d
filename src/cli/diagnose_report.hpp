#pragma once
// The report of `modalwatch diagnose`, in its directory: report.md (the steps
// before and after, the ranked candidates, the models), summary.json (the same
// steps for programs), model.yaml (the augmented model as a config), the CSV
// tables (frf.csv: the measured frequency response of the estimation part with
// its coherence, beside both models'), and the PNGs
// scripts/plot/plot_diagnose.py makes from them.
#include <string>

#include <Eigen/Core>

#include "commands.hpp"
#include "modalwatch/diagnose.hpp"
#include "modalwatch/io/config.hpp"
#include "modalwatch/record.hpp"

namespace modalwatch::cli {

// "%.*g", or null when not finite: the numbers of the report and its messages.
std::string format_number(double v, int precision = 6);

struct DiagnoseReport {
  const DiagnoseArgs& args;
  const Config& config;
  const DiagnoseResult& result;
  const Record& validation;  // as simulated: its first lead_in samples only set the state
  Eigen::Index lead_in = 0;
  const Record& estimation;  // the part the models were fitted on: its measured frequency response is frf.csv
  // The record has no sample rate: t is a sample index (a --t-column such as n
  // of whole numbers, sample_rate_hz: 1), so times are in samples and
  // frequencies in cycles/sample. summary.json's "time_unit" says which.
  bool time_in_samples = false;
};

// Writes the report into args.report (each file replaced atomically), runs
// args.plot_script on it when given, and prints the steps on stdout.
void write_diagnose_report(const DiagnoseReport& report);

// summary.json: the steps (each with its model), the stop rule and reason, and
// the unit of time ("s" or "samples"); nothing of where the records came from,
// so the same data gives the same file.
std::string diagnose_summary_json(const DiagnoseResult& result, bool time_in_samples);

}  // namespace modalwatch::cli
