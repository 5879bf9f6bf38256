// The certificate tests' common ground (test_daemon_certificate.cpp, test_daemon_equipment.cpp,
// test_daemon_audit_registry.cpp): a bench whose reference equipment and numbering a certificate
// states, and a campaign run to its end on it.
#pragma once

#include <sys/wait.h>

#include <cstdio>
#include <string>
#include <utility>

#include "daemon/production/reference_equipment.hpp"
#include "service_fixture.hpp"
#include "tests/test_paths.hpp"

namespace imucal::daemontest {

inline json certificate_campaign(const std::string& name, const std::string& serial) {
  return direct_short_calibration(name, {{"serial", serial}, {"part_number", "PN-100"}});
}

// Starts a campaign with an operator's override of the overdue table (configure_certified_bench() below names a
// table whose calibration ran out in 2020): its certificates then state the table as overdue.
inline int start_overriding(LocalDaemon& d, std::int64_t id) {
  const auto r = d.call("POST", "/api/campaigns/" + std::to_string(id) + "/start",
                        json{{"override_overdue", "test bench: the overdue table is what the certificate must state"}}.dump());
  EXPECT_EQ(r.status, 200) << r.body;
  return r.status;
}

// A campaign run to its end on the simulated bench.
inline std::int64_t run_campaign(LocalDaemon& d, const std::string& name, const std::string& serial) {
  const auto id = d.post_campaign(certificate_campaign(name, serial));
  start_overriding(d, id);
  EXPECT_EQ(d.wait_final(id).at("state"), "done");
  return id;
}

inline std::string certificate_target(std::int64_t id) { return "/api/campaigns/" + std::to_string(id) + "/certificate"; }

inline void configure_certified_bench(daemon::DaemonConfig& c, const std::string& sequence_file) {
  c.certificates.prefix = "LAB";
  c.certificates.sequence_file = sequence_file;
  c.reference_equipment.table =
      daemon::ReferenceInstrument{"Acme Motion", "ATS-3", "T-0815", "2020-01-31", "DKD-123", "1 arcsec (k=2)"};
  c.reference_equipment.chamber = daemon::ReferenceInstrument{"ClimaCo", "CC-200", "C-4711", "2999-12-31", "", ""};
  c.reference_equipment.gravity = daemon::GravitySurvey{"Federal Geodesy Agency", "GS-2024-17", "2999-12-31"};
  c.site.gravity_mps2 = 9.81912;
}

// `imucal ARGS`: its exit status and what it printed (standard output and error).
inline std::pair<int, std::string> run_imucal_cli(const std::string& args) {
  const std::string command = imucaltest::program("imucal") + " " + args + " 2>&1";
  std::string out;
  FILE* p = ::popen(command.c_str(), "r");
  if (!p) return {-1, "popen failed"};
  char buf[512];
  while (std::fgets(buf, sizeof buf, p)) out += buf;
  const int status = ::pclose(p);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}

}  // namespace imucal::daemontest
