#include "daemon/config/command_line.hpp"

#include <algorithm>
#include <cstdio>

#include <CLI/CLI.hpp>

#include "core/nearest_word.hpp"
#include "core/number_text.hpp"

namespace imucal::daemon {

namespace {

std::vector<std::string> subcommand_names(const CLI::App& app) {
  std::vector<std::string> names;
  for (const CLI::App* sub : app.get_subcommands([](const CLI::App*) { return true; }))
    if (!sub->get_name().empty()) names.push_back(sub->get_name());
  return names;
}

// The flags `app` takes, its parents' too (--help is everywhere), as they are written.
std::vector<std::string> flag_names(const CLI::App& app) {
  std::vector<std::string> names;
  for (const CLI::App* a = &app; a != nullptr; a = a->get_parent()) {
    for (const CLI::Option* opt : a->get_options()) {
      for (const std::string& l : opt->get_lnames()) names.push_back("--" + l);
      for (const std::string& s : opt->get_snames()) names.push_back("-" + s);
    }
  }
  return names;
}

std::string command_path(const CLI::App& app) {
  std::string path = app.get_name();
  for (const CLI::App* a = app.get_parent(); a != nullptr; a = a->get_parent()) path = a->get_name() + " " + path;
  return path;
}

std::string suggestion(const std::string& word, const std::vector<std::string>& known) {
  const auto near = nearest_word(word, known);
  return near ? "; did you mean '" + *near + "'?" : "";
}

}  // namespace

std::string unknown_word(const CLI::App& app, const std::vector<std::string>& args) {
  const CLI::App* at = &app;
  for (const std::string& word : args) {
    if (word == "--") break;  // the rest are values
    const bool flag = word.size() > 1 && word[0] == '-' && !parse_number_text(word);  // "-5": a value
    const auto subcommands = subcommand_names(*at);
    if (!flag) {
      if (subcommands.empty()) continue;  // a value or a positional argument of a leaf command
      const CLI::App* next = nullptr;
      for (const CLI::App* sub : at->get_subcommands([](const CLI::App*) { return true; }))
        if (sub->check_name(word)) next = sub;
      if (next == nullptr)
        return command_path(*at) + ": unknown subcommand '" + word + "'" + suggestion(word, subcommands) +
               " ('" + command_path(*at) + " --help' lists them)";
      at = next;
      continue;
    }
    const std::string name = word.substr(0, word.find('='));
    bool known = false;
    for (const CLI::App* a = at; a != nullptr && !known; a = a->get_parent())
      for (const CLI::Option* opt : a->get_options())
        if (opt->check_name(name)) known = true;
    if (!known)
      return command_path(*at) + ": unknown option '" + name + "'" + suggestion(name, flag_names(*at)) + " ('" +
             command_path(*at) + " --help' lists them)";
  }
  return {};
}

int parse_command_line(CLI::App& app, int argc, char** argv) {
  std::vector<std::string> args(argv + 1, argv + argc);
  // The words first: a mistyped flag is the mistake to fix, whatever a value beside it says.
  if (const std::string problem = unknown_word(app, args); !problem.empty()) {
    std::fprintf(stderr, "%s\n", problem.c_str());
    return kCommandLineError;
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::fprintf(stderr, "%s: %s\n('%s --help' for the options)\n", app.get_name().c_str(), e.what(), app.get_name().c_str());
    return kCommandLineError;
  }
  return -1;
}

}  // namespace imucal::daemon
