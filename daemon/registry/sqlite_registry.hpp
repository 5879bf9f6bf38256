// The registry in the daemon's own SQLite database (registry.hpp): a stand alone, as before issue
// 38. The tables are DaemonDb's; certificate numbers, with their times of issue, come from the
// site's sequence file (registry/certificate_sequence.hpp CertificateSequence), which other daemons
// on the site may share. The units' calibrations are the
// database's campaigns (named with this stand's name); the limits are the stand's limits file
// (config.limits_file), replaced whole.
#pragma once

#include <string>

#include "daemon/registry/certificate_sequence.hpp"
#include "daemon/registry/registry.hpp"

namespace imucal::daemon {

class SqliteRegistry final : public Registry {
 public:
  // `sequence`: the site's certificate numbers (outlives the registry); `stand`: this stand's name
  // (registry_stand), named by each calibration; `limits_path`: the acceptance limits file.
  SqliteRegistry(DaemonDb& db, CertificateSequence& sequence, std::string stand, std::string limits_path);

  std::string backend() const override { return "sqlite"; }
  std::int64_t next_certificate_sequence() override;
  std::int64_t max_certificate_sequence() override;
  CertificateNumber take_certificate_number() override;
  std::optional<CertificateRow> certificate(std::int64_t campaign_id) override;
  void insert_certificate(const CertificateRow& row) override;
  void insert_issued(const IssuedCertificateRow& row) override;
  std::optional<IssuedCertificateRow> issued(const std::string& number) override;
  std::optional<IssuedCertificateRow> current_issued(std::int64_t campaign_id) override;
  std::vector<IssuedCertificateRow> issued_history(std::int64_t campaign_id) override;
  std::vector<std::int64_t> campaigns_with_issued() override;
  bool insert_issued_page(const IssuedPageRow& row) override;
  std::optional<IssuedPageRow> issued_page(const std::string& number, bool with_html) override;
  void insert_overdue_override(const OverdueOverrideRow& row) override;
  void remove_overdue_override(std::int64_t campaign_id) override;
  std::optional<OverdueOverrideRow> overdue_override(std::int64_t campaign_id) override;
  AuditEntry append_audit(const std::string& actor, const std::string& action, const std::string& subject,
                          const std::string& details_json, std::optional<std::int64_t> t_ms) override;
  std::vector<AuditEntry> audit_entries(const AuditQuery& query) override;
  AuditChain audit_chain() override;
  void record_calibration(const CampaignRow& row) override;
  std::vector<CampaignRow> unit_campaigns(const std::optional<std::string>& serial) override;
  std::optional<std::string> limits_document() override;
  void put_limits_document(const std::string& document_json, const std::string& actor) override;

  // Stands: this stand alone (the daemon's own database).
  void register_stand(const StandRow& row) override;
  bool report_stand_state(const std::string& name, const std::string& state_json, std::int64_t t_ms) override;
  std::vector<StandRow> stands() override;
  void put_user(const UserRow& row) override;
  bool remove_user(const std::string& name) override;
  std::vector<UserRow> users() override;

 private:
  DaemonDb& db_;
  CertificateSequence& sequence_;
  std::string stand_;
  std::string limits_path_;
};

}  // namespace imucal::daemon
