#include "daemon/production/certificate_issuer.hpp"

#include <array>
#include <filesystem>
#include <stdexcept>

#include <spdlog/spdlog.h>

#include "core/expect_value.hpp"
#include "core/json_reader.hpp"
#include "daemon/production/certificates.hpp"
#include "daemon/production/unit_registry.hpp"

#ifndef IMUCAL_VERSION
#define IMUCAL_VERSION "0.0.0"
#endif

namespace imucal::daemon {

using nlohmann::json;

namespace {

// The keys of an issued certificate's content that name the issue itself (the software that
// issued it among them), not what it states: two contents that differ only in these state the same.
constexpr std::array<const char*, 6> kIssueKeys = {"number", "sequence", "issued", "supersedes", "reason", "software"};

json statement_of(json content) {
  for (const char* key : kIssueKeys) content.erase(key);
  return content;
}

}  // namespace

std::string no_certificate_because(const CampaignRow& row) {
  const std::string id = std::to_string(row.id);
  // A run still going (or interrupted, which can resume) could change after its certificate was issued.
  if (!is_final(row.state) || !row.ended_ms.has_value())
    return "campaign " + id + " has not ended (state " + std::string(to_string(row.state)) +
           "): a certificate is issued only for an ended run with a model";
  if (!row.model_json.has_value()) return "campaign " + id + " ended without a model: there is nothing to certify";
  if (!counts_as_calibration(row))
    return "campaign " + id + " is a partial run (" + std::string(to_string(row.state)) +
           "): a certificate is issued once an operator accepts it (POST /api/campaigns/" + id + "/accept with a reason)";
  return {};
}

json site_json(const DaemonConfig& config) {
  return {{"name", config.site_name}, {"latitude_deg", config.site.latitude_deg},
          {"longitude_deg", config.site.longitude_deg}, {"height_m", config.site.height_m},
          {"middle_axis_azimuth_deg", config.site.middle_axis_azimuth_deg}};
}

CertificateIssuer::CertificateIssuer(const DaemonConfig& config, DaemonDb& db, Registry& registry,
                                     const AuditTrail& audit, CampaignDetail detail)
    : config_(config), db_(db), registry_(registry), audit_(audit), detail_(std::move(detail)) {
  if (const std::string key = signing_key_path(config); !key.empty()) {
    signing_key_ = signing::read_key_file(key);
    spdlog::info("certificates and test reports are signed with the key {} ({})", key,
                 signing::fingerprint(signing_key_->public_key));
  }
  // Without a configuration file the sequence can only live in the data directory (a PostgreSQL
  // registry numbers from its own sequence).
  if (config.registry.postgresql.empty() && config.config_dir.empty() &&
      !std::filesystem::path(config.certificates.sequence_file).is_absolute())
    spdlog::warn("certificate numbers are counted in {} (no configuration file): a new data directory would count "
                 "again from 1; name certificates.sequence_file in a configuration file (--config)", certificate_sequence_path(config));
}

// Written as small pieces, each with an optional or two: clang 16's optional-access analysis (the
// static check) costs minutes on one function that branches on several.
std::optional<IssuedCertificateRow> CertificateIssuer::issue(std::int64_t id, const std::string& reason) {
  std::lock_guard lock(mutex_);
  const auto row = db_.campaign(id);
  if (!row) return std::nullopt;
  const CampaignRow& r = *row;
  if (!no_certificate_because(r).empty()) return registry_.current_issued(id);
  if (const auto current = registry_.current_issued(id)) return reissue(r, *current, reason);
  if (const auto legacy = registry_.certificate(id)) return freeze_legacy(r, *legacy);
  IssuedCertificateRow c = numbered(r.id, reason);
  return store_issued(c, content(r, certificate_bench_json(config_, r.ended_ms.value_or(0)).dump()));
}

IssuedCertificateRow CertificateIssuer::reissue_recalibrated(std::int64_t id, const StoreRecalibration& store) {
  std::lock_guard lock(mutex_);
  const IssuedCertificateRow current = expect_value(registry_.current_issued(id), "the certificate a recalibration supersedes");
  const std::string reason = store(current);
  return reissue(expect_value(db_.campaign(id), "the campaign calibrated again"), current, reason, true);
}

// The certificate in force, or a new one superseding it when what it states is no longer true.
IssuedCertificateRow CertificateIssuer::reissue(const CampaignRow& row, const IssuedCertificateRow& current,
                                                const std::string& reason, bool g_corrected) {
  // The bench and the site the run used, from the certificate in force (a table replaced since did
  // not calibrate this unit); what changes is what is true of the run today (its verdict, acceptance).
  const json stated = parse_or_null(current.content_json);
  json bench = stated.value("bench", json());
  if (g_corrected && bench.is_object()) {
    // Calibrated again with the corrected g: the g and the survey it now stands on.
    const json now = certificate_bench_json(config_, row.ended_ms.value_or(0));
    bench["gravity"] = now.at("gravity");
    if (bench.value("reference_equipment", json()).is_object())
      bench["reference_equipment"]["gravity"] = now.at("reference_equipment").at("gravity");
  }
  json stating = content(row, bench.dump());
  stating["site"] = stated.value("site", stating.at("site"));
  if (statement_of(stated) == statement_of(stating)) return current;
  IssuedCertificateRow c = numbered(row.id, reason);
  c.supersedes = current.number;
  return store_issued(c, std::move(stating));
}

// A number given before certificates were frozen keeps its number and date; what it states is
// frozen now, at its first reading since, with the bench kept with the number.
IssuedCertificateRow CertificateIssuer::freeze_legacy(const CampaignRow& row, const CertificateRow& legacy) {
  IssuedCertificateRow c;
  c.campaign_id = row.id;
  c.sequence = legacy.sequence;
  c.number = legacy.number;
  c.issued_ms = legacy.issued_ms;
  c.reason = "numbered before certificates were frozen; frozen at its first reading since";
  return store_issued(c, content(row, legacy.bench_json));
}

// A new number from the site's sequence (throws when it cannot be taken).
IssuedCertificateRow CertificateIssuer::numbered(std::int64_t campaign_id, const std::string& reason) {
  IssuedCertificateRow c;
  c.campaign_id = campaign_id;
  // The number and its time as one step of the registry: numbers follow the times of issue across
  // the stands sharing it (registry.hpp take_certificate_number).
  const Registry::CertificateNumber taken = registry_.take_certificate_number();
  c.sequence = taken.sequence;
  c.issued_ms = taken.issued_ms;
  c.number = certificate_number(certificate_prefix(config_), std::stoi(iso8601_utc(c.issued_ms).substr(0, 4)), c.sequence);
  c.reason = reason;
  return c;
}

// Completes the content with the issue's own keys, hashes it, signs it with the lab's key, stores
// it (superseding the old one in the same transaction) and writes the audit trail.
IssuedCertificateRow CertificateIssuer::store_issued(IssuedCertificateRow c, json content) {
  const json supersedes = c.supersedes ? json(*c.supersedes) : json(nullptr);
  content["number"] = c.number;
  content["sequence"] = c.sequence;
  content["issued"] = iso8601_utc(c.issued_ms);
  content["supersedes"] = supersedes;
  content["reason"] = c.reason;
  c.content_json = signing::canonical_json(content);
  c.content_sha256 = signing::sha256_hex(c.content_json);
  if (signing_key_) c.signed_json = signing::sign_document(content, signing::kCertificate, *signing_key_).dump();
  registry_.insert_issued(c);
  // Audited at the time the certificate states it was issued: the trail orders the issues as
  // their numbers do, not as the stands' threads got to their entries.
  audit_.append("imucald", "certificate.issued", c.number,
                {{"campaign", c.campaign_id}, {"reason", c.reason}, {"supersedes", supersedes},
                 {"content_sha256", c.content_sha256}},
                c.issued_ms);
  if (supersedes.is_string())
    audit_.append("imucald", "certificate.superseded", supersedes.get<std::string>(),
                  {{"campaign", c.campaign_id}, {"superseded_by", c.number}}, c.issued_ms);
  spdlog::info("campaign {}: certificate {} issued ({}){}", c.campaign_id, c.number, c.reason,
               supersedes.is_string() ? ", superseding " + supersedes.get<std::string>() : std::string());
  return c;
}

// What a certificate states (docs/api.md "Certificates"): the campaign as it ended, with its
// verdict under the limits in force and its acceptance; the model; the site; the software; the
// bench as configured. Frozen in the issued record: the page is rendered from this and nothing else.
json CertificateIssuer::content(const CampaignRow& row, const std::string& bench_json) {
  const json detail = detail_(row);
  json campaign = json::object();
  for (const char* key : {"id", "name", "state", "program", "started", "ended", "error", "frames", "lost_frames",
                          "bad_frames", "complete", "accepted", "verdict", "imu", "imu_serial", "progress", "transitions"})
    campaign[key] = detail.value(key, json(nullptr));
  // A run started under an override of overdue reference equipment states it (who, which, why).
  // Only such a run: the content of every other certificate stays as issued before overrides
  // were stated, so that a reissue, which compares contents, does not supersede them for nothing.
  if (const json o = detail.value("override_overdue", json()); !o.is_null()) {
    // The registry's server away (Api's overdue_override_json): no certificate states what was not read.
    if (o.contains("unavailable")) throw std::runtime_error(o.at("unavailable").get<std::string>());
    campaign["override_overdue"] = o;
  }
  const json& spec = detail.at("spec");
  campaign["spec"] = {{"chamber", spec.is_object() ? spec.value("chamber", json(nullptr)) : json(nullptr)},
                      {"estimators", spec.is_object() ? spec.value("estimators", json::array()) : json::array()}};
  return {{"format", "imucal-certificate/1"},
          {"campaign", campaign},
          {"model", parse_or_null(row.model_json)},
          {"site", site_json(config_)},
          {"software", {{"imucald", IMUCAL_VERSION}}},
          {"bench", parse_or_null(bench_json)}};
}

}  // namespace imucal::daemon
