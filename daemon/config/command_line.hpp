// The command lines of imucal and imucald (docs/cli.md, docs/daemon.md): one rule for both. A
// mistake in the words of a command line (an unknown subcommand, an unknown flag) is reported
// first, by name, with the nearest known word, before any value is checked; every command-line
// error exits with status 2, as the docs say.
#pragma once

#include <string>
#include <vector>

namespace CLI {
class App;
}

namespace imucal::daemon {

// The exit status of a command line imucal or imucald cannot run.
inline constexpr int kCommandLineError = 2;

// The first word of `args` (argv without the program name) that `app` does not know: a
// subcommand where one is expected, or a flag of the subcommand it is given to. Empty when every
// word is known. Example: "imucal: unknown subcommand 'calibrat'; did you mean 'calibrate'?".
std::string unknown_word(const CLI::App& app, const std::vector<std::string>& args);

// Parses, or says why not: -1 when the program should go on; otherwise the exit status (0 after
// --help, kCommandLineError after a message on stderr naming what is wrong).
int parse_command_line(CLI::App& app, int argc, char** argv);

}  // namespace imucal::daemon
