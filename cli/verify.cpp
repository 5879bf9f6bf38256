// imucal verify: a downloaded signed certificate or test report checked offline (docs/signing.md).
#include "cli/commands.hpp"

#include <cstdio>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>

#include "daemon/config/command_line.hpp"
#include "signing/signing.hpp"

namespace imucal::cli {

namespace {

const char* outcome_word(signing::CheckOutcome outcome) {
  switch (outcome) {
    case signing::CheckOutcome::kPassed: return "OK";
    case signing::CheckOutcome::kFailed: return "FAILED";
    case signing::CheckOutcome::kNotRun: return "NOT RUN";
    case signing::CheckOutcome::kNotChecked: return "NOT CHECKED";
  }
  return "?";
}

std::string read_text(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("cannot read " + path);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

}  // namespace

// `imucal verify FILE [--key LAB.pub | --fingerprint FP]`: each check with OK or FAILED and why.
// Exit status 0 only when all four checks pass, 1 when one fails or the key was not checked,
// 2 when the command line cannot run (a lab key that cannot be read: no check was made).
int run_verify(const std::string& document_path, const std::string& key_path, const std::string& fingerprint) {
  signing::ExpectedKey expected = signing::NoExpectedKey{};
  try {
    if (!key_path.empty()) expected = signing::read_public_key(key_path);
    if (!fingerprint.empty()) expected = signing::ExpectedFingerprint{signing::parse_fingerprint(fingerprint)};
  } catch (const std::exception& e) {
    std::fprintf(stderr, "imucal verify: %s\n", e.what());
    return daemon::kCommandLineError;
  }
  const signing::Verification v = signing::verify_document_text(read_text(document_path), expected);
  std::printf("%s\n", document_path.c_str());
  for (const signing::Check* c : v.checks())
    std::printf("  %-13s %-12s %s\n", c->name, outcome_word(c->outcome), c->message.c_str());
  std::printf("%s\n", v.message.c_str());
  return v.verified() ? 0 : 1;
}

}  // namespace imucal::cli
