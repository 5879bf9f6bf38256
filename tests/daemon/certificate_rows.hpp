// An issued certificate's row for the registry tests (test_registry.cpp, test_registry_migration.cpp):
// numbered LAB-2026-<sequence, six digits>, its time and content made from the sequence, unsigned.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <utility>

#include "daemon/db/daemon_db.hpp"

namespace imucaltest {

inline imucal::daemon::IssuedCertificateRow certificate_row(std::int64_t sequence, std::int64_t campaign,
                                                            std::optional<std::string> supersedes = std::nullopt) {
  imucal::daemon::IssuedCertificateRow r;
  r.sequence = sequence;
  r.number = "LAB-2026-" + std::to_string(1000000 + sequence).substr(1);
  r.campaign_id = campaign;
  r.issued_ms = 1700000000000 + sequence;
  r.content_json = R"({"n":)" + std::to_string(sequence) + "}";
  r.content_sha256 = "sha-" + std::to_string(sequence);
  r.reason = supersedes ? "limits changed" : "the run ended";
  r.supersedes = std::move(supersedes);
  return r;
}

}  // namespace imucaltest
