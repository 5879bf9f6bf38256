#include "daemon/registry/sqlite_registry.hpp"

#include <filesystem>
#include <fstream>
#include <sstream>
#include <utility>

#include "storage/durable_file.hpp"

namespace imucal::daemon {

namespace fs = std::filesystem;

SqliteRegistry::SqliteRegistry(DaemonDb& db, CertificateSequence& sequence, std::string stand, std::string limits_path)
    : db_(db), sequence_(sequence), stand_(std::move(stand)), limits_path_(std::move(limits_path)) {}

// The floor is the database's highest: a sequence file restored from an old backup cannot hand
// out a number again. The time is taken with the number, under the sequence file's lock: the
// daemons sharing it state their issues in the order of their numbers.
Registry::CertificateNumber SqliteRegistry::take_certificate_number() {
  const CertificateSequence::Taken taken = sequence_.take(db_.max_certificate_sequence(), now_unix_ms());
  return {taken.number, taken.issued_ms};
}
std::int64_t SqliteRegistry::next_certificate_sequence() { return take_certificate_number().sequence; }
std::int64_t SqliteRegistry::max_certificate_sequence() { return db_.max_certificate_sequence(); }

std::optional<CertificateRow> SqliteRegistry::certificate(std::int64_t campaign_id) {
  return db_.certificate(campaign_id);
}
void SqliteRegistry::insert_certificate(const CertificateRow& row) { db_.insert_certificate(row); }

void SqliteRegistry::insert_issued(const IssuedCertificateRow& row) { db_.insert_issued(row); }
std::optional<IssuedCertificateRow> SqliteRegistry::issued(const std::string& number) { return db_.issued(number); }
std::optional<IssuedCertificateRow> SqliteRegistry::current_issued(std::int64_t campaign_id) {
  return db_.current_issued(campaign_id);
}
std::vector<IssuedCertificateRow> SqliteRegistry::issued_history(std::int64_t campaign_id) {
  return db_.issued_history(campaign_id);
}
std::vector<std::int64_t> SqliteRegistry::campaigns_with_issued() { return db_.campaigns_with_issued(); }
bool SqliteRegistry::insert_issued_page(const IssuedPageRow& row) { return db_.insert_issued_page(row); }
std::optional<IssuedPageRow> SqliteRegistry::issued_page(const std::string& number, bool with_html) {
  return db_.issued_page(number, with_html);
}

void SqliteRegistry::insert_overdue_override(const OverdueOverrideRow& row) { db_.insert_overdue_override(row); }
void SqliteRegistry::remove_overdue_override(std::int64_t campaign_id) { db_.remove_overdue_override(campaign_id); }
std::optional<OverdueOverrideRow> SqliteRegistry::overdue_override(std::int64_t campaign_id) {
  return db_.overdue_override(campaign_id);
}

AuditEntry SqliteRegistry::append_audit(const std::string& actor, const std::string& action,
                                        const std::string& subject, const std::string& details_json,
                                        std::optional<std::int64_t> t_ms) {
  return db_.append_audit(actor, action, subject, details_json, t_ms);
}
std::vector<AuditEntry> SqliteRegistry::audit_entries(const AuditQuery& query) { return db_.audit_entries(query); }
AuditChain SqliteRegistry::audit_chain() { return db_.audit_chain(); }

void SqliteRegistry::register_stand(const StandRow& row) { db_.register_stand(row); }
bool SqliteRegistry::report_stand_state(const std::string& name, const std::string& state_json, std::int64_t t_ms) {
  return db_.report_stand_state(name, state_json, t_ms);
}
std::vector<StandRow> SqliteRegistry::stands() { return db_.stands(); }
void SqliteRegistry::put_user(const UserRow& row) { db_.put_user(row); }
bool SqliteRegistry::remove_user(const std::string& name) { return db_.remove_user(name); }
std::vector<UserRow> SqliteRegistry::users() { return db_.users(); }

// The database's campaign rows are the calibrations, stored as they change: nothing to add.
void SqliteRegistry::record_calibration(const CampaignRow&) {}

std::vector<CampaignRow> SqliteRegistry::unit_campaigns(const std::optional<std::string>& serial) {
  auto rows = db_.unit_campaigns(serial);
  for (CampaignRow& row : rows) row.stand = stand_;
  return rows;
}

std::optional<std::string> SqliteRegistry::limits_document() {
  std::ifstream in(limits_path_);
  if (!in) return std::nullopt;  // no file: no limits
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

// The file is the stand's; who replaced it is in the audit trail (PUT /api/limits).
void SqliteRegistry::put_limits_document(const std::string& document_json, const std::string&) {
  if (const fs::path dir = fs::path(limits_path_).parent_path(); !dir.empty()) fs::create_directories(dir);
  storage::replace_file_durably(limits_path_, document_json);
}

}  // namespace imucal::daemon
