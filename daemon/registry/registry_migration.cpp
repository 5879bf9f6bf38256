#include "daemon/registry/registry_migration.hpp"

#include <algorithm>
#include <limits>
#include <map>
#include <stdexcept>
#include <utility>

#include <nlohmann/json.hpp>

#include "daemon/registry/calibrations.hpp"
#include "daemon/registry/postgres_registry.hpp"

namespace imucal::daemon {

namespace {

using nlohmann::json;

constexpr const char* kOriginKey = "migrated_from";

// A refusal of the lab's server (a unique key another stand's row holds) is a conflict to name,
// not a failure of the server: the caller is told which row and that nothing was copied.
template <class Write>
void write_or_conflict(const std::string& what, Write&& write) {
  try {
    write();
  } catch (const storage::pg::PgError& e) {
    if (e.connection_lost()) throw;
    throw MigrationError(what + ": the lab's registry refused it (" + e.what() +
                         "): another stand's row holds its number or key; nothing was copied");
  }
}

std::string certificate_name(const std::string& number, std::int64_t sequence, std::int64_t campaign_id) {
  return "certificate " + number + " (sequence " + std::to_string(sequence) + ", campaign " +
         std::to_string(campaign_id) + ")";
}

// One migration: the stand's rows read once, copied into the lab's transaction step by step.
class Copier {
 public:
  Copier(const StandRegistrySource& source, PostgresRegistry& lab, MigrationReport& report)
      : src_(source), db_(*source.db), lab_(lab), report_(report) {
    report_.counts.reserve(8);  // each step holds a reference to its count while it copies
    for (const CampaignRow& c : db_.campaigns(std::numeric_limits<std::int64_t>::max())) campaign_ids_.push_back(c.id);
    std::sort(campaign_ids_.begin(), campaign_ids_.end());
  }

  void certificate_numbers() {
    MigrationCount& n = count("certificate numbers (before issue 35)");
    for (const std::int64_t id : campaign_ids_) {
      const auto row = db_.certificate(id);
      if (!row) continue;
      const std::string what = "campaign " + std::to_string(id) + "'s certificate number " + row->number;
      if (const auto there = lab_.certificate(id)) {
        if (there->number != row->number || there->sequence != row->sequence)
          throw MigrationError(what + ": the lab's registry gives stand '" + src_.stand + "''s campaign " +
                               std::to_string(id) + " the number " + there->number + " already; nothing was copied");
        ++n.skipped;
        continue;
      }
      write_or_conflict(what, [&] { lab_.insert_certificate(*row); });
      ++n.copied;
    }
  }

  // In issue order (the sequence), so that a superseding certificate finds the one it replaces
  // and marks it, as when it was issued.
  void issued_certificates() {
    MigrationCount& n = count("issued certificates");
    for (const std::int64_t id : campaign_ids_)
      for (IssuedCertificateRow& row : db_.issued_history(id)) issued_.push_back(std::move(row));
    std::sort(issued_.begin(), issued_.end(), [](const auto& a, const auto& b) { return a.sequence < b.sequence; });
    for (const IssuedCertificateRow& row : issued_) {
      const std::string what = certificate_name(row.number, row.sequence, row.campaign_id);
      if (const auto there = lab_.issued(row.number)) {
        if (there->sequence != row.sequence || there->campaign_id != row.campaign_id ||
            there->content_sha256 != row.content_sha256)
          throw MigrationError(what + ": the lab's registry holds another certificate of that number (" +
                               certificate_name(there->number, there->sequence, there->campaign_id) +
                               ", content " + there->content_sha256 + "); nothing was copied");
        ++n.skipped;
        continue;
      }
      IssuedCertificateRow copy = row;
      copy.superseded_by.reset();  // set by the one that supersedes it, inserted after it
      write_or_conflict(what, [&] { lab_.insert_issued(copy); });
      ++n.copied;
    }
  }

  void printed_pages() {
    MigrationCount& n = count("printed pages");
    for (const IssuedCertificateRow& row : issued_) {
      const auto page = db_.issued_page(row.number, true);
      if (!page) continue;
      if (const auto there = lab_.issued_page(row.number, false)) {
        if (there->sha256 != page->sha256)
          throw MigrationError("the printed page of certificate " + row.number + ": the lab's registry holds another (" +
                               there->sha256 + ", not " + page->sha256 + "); nothing was copied");
        ++n.skipped;
        continue;
      }
      write_or_conflict("the printed page of certificate " + row.number, [&] { lab_.insert_issued_page(*page); });
      ++n.copied;
    }
  }

  void overdue_overrides() {
    MigrationCount& n = count("overdue overrides");
    for (const std::int64_t id : campaign_ids_) {
      const auto row = db_.overdue_override(id);
      if (!row) continue;
      const std::string what = "campaign " + std::to_string(id) + "'s overdue override by " + row->by;
      if (const auto there = lab_.overdue_override(id)) {
        if (there->t_ms != row->t_ms || there->by != row->by || there->reason != row->reason)
          throw MigrationError(what + ": the lab's registry holds another for stand '" + src_.stand + "''s campaign " +
                               std::to_string(id) + " (by " + there->by + "); nothing was copied");
        ++n.skipped;
        continue;
      }
      write_or_conflict(what, [&] { lab_.insert_overdue_override(*row); });
      ++n.copied;
    }
  }

  // The stand's database states a campaign's row last (the stand records it from there), so a
  // row the lab holds that differs is recorded again, not a conflict.
  void calibrations() {
    MigrationCount& n = count("calibrations");
    std::map<std::int64_t, std::string> there;
    for (const CampaignRow& row : lab_.unit_campaigns(std::nullopt))
      if (row.stand == src_.stand) there[row.id] = campaign_row_json(row);
    for (const CampaignRow& row : db_.unit_campaigns(std::nullopt)) {
      const auto it = there.find(row.id);
      if (it != there.end() && it->second == campaign_row_json(row)) {
        ++n.skipped;
        continue;
      }
      lab_.record_calibration(row);
      ++(it == there.end() ? n.copied : n.updated);
    }
  }

  // The stand's own accounts of the lab kind: an account the lab has under that name already is
  // the lab's (kept, said in a note when it differs), the others copied.
  void accounts() {
    MigrationCount& n = count("accounts");
    std::map<std::string, UserRow> there;
    for (const UserRow& u : lab_.users()) there[u.name] = u;
    for (const UserRow& u : db_.users()) {
      const auto it = there.find(u.name);
      if (it == there.end()) {
        lab_.put_user(u);
        ++n.copied;
        continue;
      }
      ++n.skipped;
      if (it->second.role != u.role || it->second.password_hash != u.password_hash)
        report_.notes.push_back("the lab's registry has an account '" + u.name + "' of its own, which differs from the "
                                "stand's: it was kept");
    }
  }

  void limits() {
    MigrationCount& n = count("limits document");
    if (!src_.limits_json) return;
    const std::string& text = *src_.limits_json;
    const auto there = lab_.limits_document();
    if (!there) {
      lab_.put_limits_document(text, src_.actor);
      ++n.copied;
      return;
    }
    const json mine = json::parse(text, nullptr, false);
    const json theirs = json::parse(*there, nullptr, false);
    if (!mine.is_discarded() && mine == theirs) {
      ++n.skipped;
      return;
    }
    // The lab's limits judge every stand's runs: one stand moving in does not replace them.
    report_.notes.push_back("the lab's registry has limits of its own, which differ from the stand's: they were kept "
                            "(put the stand's with PUT /api/limits on a stand if they are to replace them)");
  }

  void audit_trail(const std::vector<AuditEntry>& chain) {
    MigrationCount& n = count("audit entries");
    // The stand's entries the lab holds already: a prefix of its chain, appended by an earlier run.
    std::optional<AuditEntry> last_there;
    for (const AuditEntry& e : lab_.audit_trail())
      if (auto origin = migrated_origin(e); origin && origin->stand == src_.stand) last_there = std::move(origin->original);
    std::size_t done = 0;
    if (last_there) {
      done = static_cast<std::size_t>(std::max<std::int64_t>(last_there->seq, 0));
      if (done == 0 || done > chain.size() || chain[done - 1].sha256 != last_there->sha256)
        throw MigrationError("the lab's registry holds audit entries 1 to " + std::to_string(done) + " of a stand '" +
                             src_.stand + "' whose chain is not this one (entry " + std::to_string(done) +
                             "'s hash differs): is '" + src_.stand + "' another stand's name? nothing was copied");
    }
    n.skipped = static_cast<std::int64_t>(done);
    for (std::size_t i = done; i < chain.size(); ++i) {
      const AuditEntry& e = chain[i];
      const AuditEntry appended =
          lab_.append_audit(e.actor, e.action, e.subject, migrated_details_json(e, src_.stand), e.t_ms);
      if (report_.first_lab_audit_seq == 0) report_.first_lab_audit_seq = appended.seq;
      report_.last_lab_audit_seq = appended.seq;
      ++n.copied;
    }
  }

  // The migration itself, in the lab's trail, when it copied anything.
  void summary_entry(const std::vector<AuditEntry>& chain) {
    json copied = json::object();
    std::int64_t total = 0;
    for (const MigrationCount& c : report_.counts) {
      copied[c.what] = {{"copied", c.copied}, {"updated", c.updated}, {"skipped", c.skipped}};
      total += c.copied + c.updated;
    }
    if (total == 0) return;
    json details = {{"stand", src_.stand}, {"from", src_.label}, {"counts", copied}};
    if (!chain.empty()) details["source_head"] = {{"seq", chain.back().seq}, {"sha256", chain.back().sha256}};
    report_.last_lab_audit_seq =
        lab_.append_audit(src_.actor, "registry.migrated", "stand " + src_.stand, details.dump(), std::nullopt).seq;
  }

 private:
  MigrationCount& count(const std::string& what) {
    report_.counts.push_back(MigrationCount{what});
    return report_.counts.back();
  }

  const StandRegistrySource& src_;
  DaemonDb& db_;
  PostgresRegistry& lab_;
  MigrationReport& report_;
  std::vector<std::int64_t> campaign_ids_;
  std::vector<IssuedCertificateRow> issued_;
};

// The stand's chain, checked by the one rule before anything is copied.
std::vector<AuditEntry> checked_source_chain(const StandRegistrySource& source) {
  AuditChain chain = source.db->audit_chain();
  const AuditCheck check = check_audit_chain(chain);
  if (!check.ok())
    throw MigrationError("the audit trail of " + source.label + " does not hold: " + check.message +
                         "; nothing was copied (imucal audit verify " + source.label + ")");
  return std::move(chain.entries);
}

}  // namespace

std::int64_t MigrationReport::copied() const {
  std::int64_t n = 0;
  for (const MigrationCount& c : counts) n += c.copied + c.updated;
  return n;
}

std::int64_t MigrationReport::skipped() const {
  std::int64_t n = 0;
  for (const MigrationCount& c : counts) n += c.skipped;
  return n;
}

const MigrationCount& MigrationReport::count(const std::string& what) const {
  for (const MigrationCount& c : counts)
    if (c.what == what) return c;
  throw std::out_of_range("no migration count '" + what + "'");
}

MigrationReport migrate_stand_registry(const StandRegistrySource& source, PostgresRegistry& lab, bool dry_run) {
  if (source.db == nullptr) throw std::invalid_argument("migrate_stand_registry: no source database");
  MigrationReport report;
  report.dry_run = dry_run;
  const std::vector<AuditEntry> chain = checked_source_chain(source);
  report.source_audit_entries = static_cast<std::int64_t>(chain.size());
  report.highest_sequence = source.db->max_certificate_sequence();
  report.lab_schema_version = lab.schema_version();
  report.lab_sequence_before = lab.last_certificate_sequence();
  std::int64_t lab_highest = 0;
  lab.in_one_transaction(
      [&] {
        Copier copier(source, lab, report);
        copier.certificate_numbers();
        copier.issued_certificates();
        copier.printed_pages();
        copier.overdue_overrides();
        copier.calibrations();
        copier.accounts();
        copier.limits();
        copier.audit_trail(chain);
        copier.summary_entry(chain);
        lab_highest = lab.max_certificate_sequence();
      },
      !dry_run);
  // After the commit: a sequence moved for a migration that then failed would only leave a gap.
  const std::int64_t at_least = std::max(report.highest_sequence, lab_highest);
  report.lab_sequence_after =
      dry_run ? std::max(report.lab_sequence_before, at_least) : lab.raise_certificate_sequence(at_least);
  return report;
}

std::vector<std::string> MigrationReport::lines() const {
  std::vector<std::string> out;
  const std::string verb = dry_run ? "would be copied" : "copied";
  out.push_back("the stand's audit trail: intact, " + std::to_string(source_audit_entries) + " entries");
  for (const MigrationCount& c : counts) {
    std::string line = c.what + ": " + std::to_string(c.copied) + " " + verb;
    if (c.updated > 0)
      line += ", " + std::to_string(c.updated) + (dry_run ? " would be" : "") +
              " recorded again (the stand's row is newer)";
    line += ", " + std::to_string(c.skipped) + " skipped (in the lab's registry already)";
    if (c.what == "audit entries" && c.copied > 0)
      line += "; as the lab's entries " + std::to_string(first_lab_audit_seq) + " to " +
              std::to_string(first_lab_audit_seq + c.copied - 1) + ", each naming its origin";
    out.push_back(line);
  }
  out.push_back("certificate numbers: the stand's highest sequence number is " + std::to_string(highest_sequence) +
                "; the lab's next number " + (dry_run ? "would be " : "is ") + std::to_string(lab_sequence_after + 1) +
                " (its last was " + std::to_string(lab_sequence_before) + ")");
  for (const std::string& note : notes) out.push_back("note: " + note);
  return out;
}

// ---- The migrated entries' origin ------------------------------------------------------------

std::string migrated_details_json(const AuditEntry& original, const std::string& stand) {
  json origin = {{"stand", stand},
                 {"seq", original.seq},
                 {"sha256", original.sha256},
                 {"prev_sha256", original.prev_sha256}};
  json details = json::parse(original.details_json, nullptr, false);
  // Details that are no JSON object (a database edited by hand) travel as their exact text.
  if (!details.is_object() || details.contains(kOriginKey)) {
    origin["details_json"] = original.details_json;
    return json{{kOriginKey, origin}}.dump();
  }
  details[kOriginKey] = std::move(origin);
  return details.dump();
}

std::optional<MigratedOrigin> migrated_origin(const AuditEntry& lab_entry) {
  json details = json::parse(lab_entry.details_json, nullptr, false);
  if (!details.is_object() || !details.contains(kOriginKey) || !details.at(kOriginKey).is_object())
    return std::nullopt;
  try {
    const json origin = details.at(kOriginKey);
    MigratedOrigin out;
    out.stand = origin.at("stand").get<std::string>();
    out.original = lab_entry;
    out.original.seq = origin.at("seq").get<std::int64_t>();
    out.original.sha256 = origin.at("sha256").get<std::string>();
    out.original.prev_sha256 = origin.at("prev_sha256").get<std::string>();
    if (origin.contains("details_json")) {
      out.original.details_json = origin.at("details_json").get<std::string>();
    } else {
      details.erase(kOriginKey);
      out.original.details_json = details.dump();
    }
    return out;
  } catch (const json::exception&) {
    return std::nullopt;  // no origin that can be read: the stand's chain shows the entry missing
  }
}

bool LabAuditCheck::ok() const {
  return lab.ok() && std::all_of(stands.begin(), stands.end(), [](const auto& s) { return s.second.ok(); });
}

LabAuditCheck check_lab_audit_chain(const std::vector<AuditEntry>& entries,
                                    const std::optional<std::pair<std::int64_t, std::string>>& head) {
  LabAuditCheck out;
  out.lab = check_audit_chain(entries, head);
  std::vector<std::string> order;
  std::map<std::string, std::vector<AuditEntry>> by_stand;
  for (const AuditEntry& e : entries) {
    auto origin = migrated_origin(e);
    if (!origin) continue;
    auto [it, inserted] = by_stand.try_emplace(origin->stand);
    if (inserted) order.push_back(origin->stand);
    it->second.push_back(std::move(origin->original));
  }
  for (const std::string& stand : order) out.stands.emplace_back(stand, check_audit_chain(by_stand[stand], std::nullopt));
  return out;
}

}  // namespace imucal::daemon
