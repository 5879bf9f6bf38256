#include "daemon/db/audit_chain.hpp"

#include <nlohmann/json.hpp>

#include "signing/signing.hpp"

namespace imucal::daemon {

std::string audit_entry_sha256(const AuditEntry& e) {
  // Details that are not JSON (the database edited by hand) are hashed as the text they are.
  nlohmann::json details = nlohmann::json::parse(e.details_json, nullptr, false);
  if (details.is_discarded()) details = e.details_json;
  const nlohmann::json fields = {{"seq", e.seq},         {"t_ms", e.t_ms},       {"actor", e.actor},
                                 {"action", e.action},   {"subject", e.subject}, {"details", details},
                                 {"prev_sha256", e.prev_sha256}};
  return signing::sha256_hex(signing::canonical_json(fields));
}

AuditCheck check_audit_chain(const std::vector<AuditEntry>& entries,
                             const std::optional<std::pair<std::int64_t, std::string>>& head) {
  AuditCheck out;
  std::string prev = kAuditGenesis;
  std::int64_t expected_seq = 1;
  const auto bad = [&out](std::int64_t seq, const std::string& why) {
    out.first_bad = seq;
    out.message = "audit entry " + std::to_string(seq) + ": " + why;
    return out;
  };
  for (const AuditEntry& e : entries) {
    ++out.entries;
    if (e.seq != expected_seq)
      return bad(e.seq, e.seq > expected_seq
                            ? "entries " + std::to_string(expected_seq) + " to " + std::to_string(e.seq - 1) +
                                  " before it are missing (deleted)"
                            : "out of order (expected " + std::to_string(expected_seq) + ")");
    if (e.prev_sha256 != prev)
      return bad(e.seq, "its link to the entry before does not match that entry's hash (the entry before was "
                        "changed, or replaced)");
    if (audit_entry_sha256(e) != e.sha256)
      return bad(e.seq, "changed after it was written (its fields no longer give its hash)");
    prev = e.sha256;
    ++expected_seq;
  }
  if (head) {
    const auto& [head_seq, head_sha] = *head;
    if (head_seq != expected_seq - 1 || head_sha != prev)
      return bad(expected_seq, "the trail ends at entry " + std::to_string(expected_seq - 1) +
                                   " but the database recorded entry " + std::to_string(head_seq) +
                                   " as its last: entries at the end were deleted");
  }
  out.message = "audit trail intact: " + std::to_string(out.entries) + " entries, each linked to the one before";
  return out;
}

AuditEntry next_audit_entry(const std::optional<std::pair<std::int64_t, std::string>>& last, AuditFields fields) {
  AuditEntry e;
  e.seq = last ? last->first + 1 : 1;
  e.prev_sha256 = last ? last->second : std::string(kAuditGenesis);
  e.t_ms = fields.t_ms;
  e.actor = std::move(fields.actor);
  e.action = std::move(fields.action);
  e.subject = std::move(fields.subject);
  e.details_json = std::move(fields.details_json);
  e.sha256 = audit_entry_sha256(e);
  return e;
}

}  // namespace imucal::daemon
