// imucal passwd: the hash of a password for imucald's configuration.
#include "cli/commands.hpp"

#include <termios.h>
#include <unistd.h>

#include <cstdio>
#include <iostream>
#include <string>

#include "daemon/config/password_hash.hpp"

namespace imucal::cli {

namespace {

// One line from standard input; on a terminal without echo, after a prompt on stderr.
std::string read_secret(const char* prompt) {
  const bool tty = ::isatty(STDIN_FILENO) != 0;
  termios saved{};
  if (tty) {
    std::fprintf(stderr, "%s", prompt);
    ::tcgetattr(STDIN_FILENO, &saved);
    termios quiet = saved;
    quiet.c_lflag &= ~static_cast<tcflag_t>(ECHO);
    ::tcsetattr(STDIN_FILENO, TCSANOW, &quiet);
  }
  std::string line;
  const bool got = static_cast<bool>(std::getline(std::cin, line));
  if (tty) {
    ::tcsetattr(STDIN_FILENO, TCSANOW, &saved);
    std::fprintf(stderr, "\n");
  }
  if (!got) throw std::runtime_error("no password on standard input");
  if (!line.empty() && line.back() == '\r') line.pop_back();
  return line;
}

}  // namespace

// `imucal passwd`: the hash for a user's "password_hash" in imucald's configuration.
int run_passwd() {
  const std::string password = read_secret("password: ");
  if (password.size() < daemon::kMinPasswordLength)
    throw std::runtime_error("the password must have at least " + std::to_string(daemon::kMinPasswordLength) +
                             " characters");
  if (::isatty(STDIN_FILENO) != 0 && read_secret("again: ") != password) throw std::runtime_error("the two do not match");
  std::printf("%s\n", imucal::daemon::hash_password(password).c_str());
  std::fprintf(stderr, "put it in imucald's configuration as a user's \"password_hash\" (docs/daemon.md)\n");
  return 0;
}

}  // namespace imucal::cli
