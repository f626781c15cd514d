#pragma once
// The plot scripts (scripts/plot/) that `fit` and `diagnose` run on the CSV
// tables they write, with Debian's python3 and matplotlib.
#include <string>

namespace modalwatch::cli {

struct PlotOutcome {
  bool made = false;
  std::string failure;  // why not, when the script was given
};

// python3 SCRIPT DIR, without a shell: the paths are arguments, never parsed.
// The script's stderr is collected and shown; its stdout is the command's.
PlotOutcome run_plot_script(const std::string& script, const std::string& dir);

}  // namespace modalwatch::cli
