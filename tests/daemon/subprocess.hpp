// The daemon's executables as subprocesses in the tests: started with their stdout on a pipe (what
// they announce: the port they listen on, the configuration they print) and their stderr appended
// to a log file, then read until what is awaited has come, and waited for.
#pragma once

#include <poll.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <fcntl.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <thread>
#include <vector>

namespace imucal::daemontest {

struct Child {
  pid_t pid = -1;
  int stdout_fd = -1;  // the read end of the child's stdout; -1 once read
};

// Starts argv[0] with argv; pid -1 when it cannot (the test then fails on what it awaited). With
// `core_dir`, the child runs there and may dump core (a kernel whose core_pattern is a plain name
// writes it there), so that a child that dies of a signal in a long soak leaves its stacks.
inline Child spawn_child(const std::vector<std::string>& argv, const std::string& log_path,
                         const std::string& core_dir = {}) {
  int out[2];
  if (::pipe(out) != 0) return {};
  const pid_t pid = ::fork();
  if (pid == 0) {
    if (!core_dir.empty() && ::chdir(core_dir.c_str()) == 0) {
      rlimit core{};
      if (::getrlimit(RLIMIT_CORE, &core) == 0) {
        core.rlim_cur = core.rlim_max;
        ::setrlimit(RLIMIT_CORE, &core);
      }
    }
    ::dup2(out[1], STDOUT_FILENO);
    const int err = ::open(log_path.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
    if (err >= 0) ::dup2(err, STDERR_FILENO);
    ::close(out[0]);
    ::close(out[1]);
    std::vector<char*> args;
    for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);
    ::execv(args[0], args.data());
    ::_exit(127);
  }
  ::close(out[1]);
  if (pid < 0) {
    ::close(out[0]);
    return {};
  }
  return {pid, out[0]};
}

// Reads the child's stdout until done(text so far) holds, the pipe ends or timeout_s passes;
// closes the pipe and returns the text.
inline std::string read_stdout_until(Child& child, const std::function<bool(const std::string&)>& done,
                                     double timeout_s) {
  std::string text;
  if (child.stdout_fd < 0) return text;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (std::chrono::steady_clock::now() < deadline && !done(text)) {
    pollfd p{child.stdout_fd, POLLIN, 0};
    if (::poll(&p, 1, 200) <= 0) continue;
    char buf[1024];
    const auto n = ::read(child.stdout_fd, buf, sizeof buf);
    if (n <= 0) break;
    text.append(buf, static_cast<std::size_t>(n));
  }
  ::close(child.stdout_fd);
  child.stdout_fd = -1;
  return text;
}

// The exit status as wait_exit gives it when the child has ended (and is reaped), else nullopt.
inline std::optional<int> exited(pid_t pid) {
  int status = 0;
  if (::waitpid(pid, &status, WNOHANG) != pid) return std::nullopt;
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

// The exit status (128 + signal when killed); after timeout_s the child is killed and -1 returned.
inline int wait_exit(pid_t pid, double timeout_s) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (std::chrono::steady_clock::now() < deadline) {
    if (const auto status = exited(pid)) return *status;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ::kill(pid, SIGKILL);
  ::waitpid(pid, nullptr, 0);
  return -1;
}

// The real imucald as a subprocess on a free loopback port (its "listening on" line read from its
// stdout; port 0 when it did not start), signed with the tests' operator token. It runs in its
// log's directory, where a crash leaves its core.
struct DaemonProcess {
  pid_t pid = -1;
  std::uint16_t port = 0;
};
inline DaemonProcess spawn_imucald(const std::string& imucald, const std::string& data_dir, const std::string& log_path,
                                   const std::string& operator_token, const char* devices = "sim",
                                   const std::vector<std::string>& more_args = {}) {
  std::vector<std::string> args = {imucald,         "--listen",    "127.0.0.1:0", "--data-dir", data_dir,
                                   "--operator-token", operator_token, "--log-level", "info",       "--devices",
                                   devices};
  args.insert(args.end(), more_args.begin(), more_args.end());
  const auto slash = log_path.rfind('/');
  Child child = spawn_child(args, log_path, slash == std::string::npos ? std::string(".") : log_path.substr(0, slash));
  constexpr const char* kListening = "listening on http://127.0.0.1:";
  const std::string text = read_stdout_until(
      child,
      [&](const std::string& t) {
        const auto at = t.find(kListening);
        return at != std::string::npos && t.find('\n', at) != std::string::npos;
      },
      60.0);
  DaemonProcess d;
  d.pid = child.pid;
  if (const auto at = text.find(kListening); at != std::string::npos)
    d.port = static_cast<std::uint16_t>(std::stoi(text.substr(at + std::string(kListening).size())));
  return d;
}

}  // namespace imucal::daemontest
