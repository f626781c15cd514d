#pragma once
// Errors at the edges (configuration files, records). The numerical core never
// throws these; the CLI maps them to exit code 2.
#include <stdexcept>
#include <string>

namespace modalwatch {

// A problem with something a user wrote: a YAML key, a CSV cell, a CLI flag.
// `location` says where ("paper-sim.yaml:12: key 'model.submodels[0].wn'" or
// "run.csv: row 17, column 'y'") so the message can be acted on without a debugger.
class InputError : public std::runtime_error {
 public:
  InputError(std::string location, const std::string& message)
      : std::runtime_error(location.empty() ? message : location + ": " + message), location_(std::move(location)) {}
  const std::string& location() const { return location_; }

 private:
  std::string location_;
};

}  // namespace modalwatch
