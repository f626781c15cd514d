// The plot scripts (scripts/plot/) the offline commands run on their output.
#include "plot_script.hpp"

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <vector>

extern char** environ;

namespace modalwatch::cli {

PlotOutcome run_plot_script(const std::string& script, const std::string& dir) {
  static const std::string python = "/usr/bin/python3";  // the script's interpreter (Debian's matplotlib)
  std::vector<std::string> args{python, script, dir};
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  int err[2];
  if (pipe2(err, O_CLOEXEC) != 0) return {false, std::string("cannot make a pipe: ") + std::strerror(errno)};
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_adddup2(&actions, err[1], STDERR_FILENO);
  std::fflush(stdout);
  pid_t pid = 0;
  const int spawned = posix_spawn(&pid, python.c_str(), &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  close(err[1]);
  if (spawned != 0) {
    close(err[0]);
    return {false, "cannot run " + python + ": " + std::strerror(spawned)};
  }
  std::string text;
  char buf[4096];
  for (;;) {
    const ssize_t n = read(err[0], buf, sizeof buf);
    if (n > 0)
      text.append(buf, static_cast<std::size_t>(n));
    else if (n == 0 || errno != EINTR)
      break;
  }
  close(err[0]);
  int status = 0;
  while (waitpid(pid, &status, 0) < 0)
    if (errno != EINTR) return {false, std::string("waitpid: ") + std::strerror(errno)};
  if (!text.empty()) std::fprintf(stderr, "%s%s", text.c_str(), text.back() == '\n' ? "" : "\n");
  if (WIFEXITED(status) && WEXITSTATUS(status) == 0) return {true, ""};
  const std::string how = WIFEXITED(status) ? "exited with status " + std::to_string(WEXITSTATUS(status))
                                            : "killed by signal " + std::to_string(WTERMSIG(status));
  return {false, python + " " + script + " " + how};
}

}  // namespace modalwatch::cli
