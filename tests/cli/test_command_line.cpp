// The command-line rule of imucal and imucald (daemon/config/command_line.hpp): unknown words
// named first, with the nearest known one.
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <gtest/gtest.h>

#include "core/nearest_word.hpp"
#include "daemon/config/command_line.hpp"

using imucal::nearest_word;
using imucal::daemon::unknown_word;

namespace {

// A small imucal: calibrate (--db, --out), campaign run (--time-scale).
struct Commands {
  CLI::App app{"test", "imucal"};
  std::string db, out, file;
  double time_scale = 0;
  Commands() {
    auto* cal = app.add_subcommand("calibrate", "");
    cal->add_option("--db", db)->check(CLI::ExistingFile);
    cal->add_option("-o,--out", out);
    auto* camp = app.add_subcommand("campaign", "");
    auto* run = camp->add_subcommand("run", "");
    run->add_option("file", file);
    run->add_option("--time-scale", time_scale);
  }
};

}  // namespace

TEST(CommandLine, NearestWordIsOfferedOnlyWhenItIsNear) {
  const std::vector<std::string> known = {"simulate", "calibrate", "campaign", "compare"};
  EXPECT_EQ(nearest_word("calibrat", known), "calibrate");
  EXPECT_EQ(nearest_word("campain", known), "campaign");
  EXPECT_EQ(nearest_word("comapre", known), "compare");
  EXPECT_FALSE(nearest_word("frobnicate", known).has_value());
  EXPECT_FALSE(nearest_word("x", known).has_value());
  EXPECT_EQ(nearest_word("--dbb", {"--db", "--out", "--help"}), "--db");
}

TEST(CommandLine, AnUnknownSubcommandIsNamedWithTheNearestOne) {
  Commands c;
  EXPECT_EQ(unknown_word(c.app, {"calibrat", "--db", "x.db"}),
            "imucal: unknown subcommand 'calibrat'; did you mean 'calibrate'? ('imucal --help' lists them)");
  EXPECT_EQ(unknown_word(c.app, {"campaign", "rn", "c.json"}),
            "imucal campaign: unknown subcommand 'rn'; did you mean 'run'? ('imucal campaign --help' lists them)");
  EXPECT_EQ(unknown_word(c.app, {"zzzzzz"}), "imucal: unknown subcommand 'zzzzzz' ('imucal --help' lists them)");
}

TEST(CommandLine, AnUnknownFlagIsNamedBeforeAnyValueIsChecked) {
  Commands c;
  // --db names a file that does not exist: the typo in --outt is still the first thing said.
  EXPECT_EQ(unknown_word(c.app, {"calibrate", "--db", "/no/such.db", "--outt", "m.json"}),
            "imucal calibrate: unknown option '--outt'; did you mean '--out'? ('imucal calibrate --help' lists them)");
  EXPECT_EQ(unknown_word(c.app, {"campaign", "run", "c.json", "--time-scal=3"}),
            "imucal campaign run: unknown option '--time-scal'; did you mean '--time-scale'? ('imucal campaign run --help' lists them)");
}

TEST(CommandLine, KnownWordsNegativeNumbersAndValuesAfterTheMarkerPass) {
  Commands c;
  EXPECT_EQ(unknown_word(c.app, {"calibrate", "--db", "x.db", "-o", "m.json"}), "");
  EXPECT_EQ(unknown_word(c.app, {"calibrate", "--help"}), "");
  EXPECT_EQ(unknown_word(c.app, {"campaign", "run", "c.json", "--time-scale", "-1"}), "");
  EXPECT_EQ(unknown_word(c.app, {"campaign", "run", "--time-scale=-2.5e-1", "--", "--not-a-flag"}), "");
}
