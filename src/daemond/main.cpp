// modalwatchd --config C.yaml: the daemon under systemd (Type=notify).
//
// The signals are blocked in every thread and taken here with sigtimedwait, so
// the handlers are ordinary code: SIGTERM/SIGINT stop (drain, checkpoint, exit
// 0), SIGHUP reloads the config (a bad file keeps the running one). Exit code 2
// for a bad config or an LCM URL that cannot be opened, 1 for anything else.
#include <signal.h>
#include <systemd/sd-daemon.h>

#include <cstdio>
#include <ctime>
#include <exception>
#include <optional>
#include <string>

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>
#include <CLI/CLI.hpp>

#include "modalwatch/daemon/daemon.hpp"
#include "modalwatch/error.hpp"
#include "modalwatch/io/config.hpp"
#include "modalwatch_version.hpp"

namespace {

void set_up_logging() {
  auto logger = spdlog::stderr_color_mt("modalwatchd");
  // The journal adds its own time stamp, but the same lines also go to terminals and test logs.
  logger->set_pattern("%Y-%m-%d %H:%M:%S.%e %^%l%$ %v");
  spdlog::set_default_logger(logger);
  spdlog::flush_on(spdlog::level::info);
}

int run(const std::string& config_path) {
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGHUP);
  // Before any thread exists, so that every thread inherits the mask.
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  modalwatch::Config config;
  try {
    config = modalwatch::load_config(config_path);
  } catch (const modalwatch::InputError& e) {
    spdlog::critical("bad configuration: {}", e.what());
    return 2;
  }
  spdlog::set_level(spdlog::level::from_str(config.daemon.log_level));
  std::optional<modalwatch::Daemon> daemon;
  try {
    daemon.emplace(config);
  } catch (const modalwatch::InputError& e) {
    spdlog::critical("cannot start: {}", e.what());
    return 2;
  } catch (const std::invalid_argument& e) {  // estimator or fault detector settings
    spdlog::critical("cannot start: {}: {}", config_path, e.what());
    return 2;
  }
  daemon->start();
  sd_notify(0, "READY=1\nSTATUS=estimating");

  for (;;) {
    siginfo_t info{};
    const timespec timeout{1, 0};
    const int sig = sigtimedwait(&signals, &info, &timeout);
    if (sig < 0) continue;  // timeout or EINTR
    if (sig == SIGHUP) {
      sd_notify(0, "RELOADING=1");
      spdlog::info("SIGHUP: reloading {}", config_path);
      try {
        const modalwatch::Config next = modalwatch::load_config(config_path);
        spdlog::info("{}", daemon->reload(next));
      } catch (const modalwatch::InputError& e) {
        spdlog::error("reload rejected, keeping the running configuration: {}", e.what());
      } catch (const std::invalid_argument& e) {
        spdlog::error("reload rejected, keeping the running configuration: {}", e.what());
      }
      sd_notify(0, "READY=1\nSTATUS=estimating");
      continue;
    }
    spdlog::info("{}: draining and stopping", sig == SIGTERM ? "SIGTERM" : "SIGINT");
    sd_notify(0, "STOPPING=1");
    daemon->stop();
    daemon->write_checkpoint();  // logs success or failure itself
    daemon.reset();
    return 0;
  }
}

}  // namespace

int main(int argc, char** argv) {
  set_up_logging();
  CLI::App app{"modalwatchd: online modal estimation and fault flags from LCM samples"};
  std::string config_path;
  app.set_version_flag("--version", "modalwatchd " MODALWATCH_VERSION);
  app.add_option("--config", config_path, "YAML configuration (config/README.md)")->required();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? 0 : 2;
  }
  try {
    return run(config_path);
  } catch (const std::exception& e) {
    spdlog::critical("modalwatchd: {}", e.what());
    return 1;
  }
}
