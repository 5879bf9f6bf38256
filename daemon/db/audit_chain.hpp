// The audit trail's chain (issue 35, docs/daemon.md "Audit trail"): every change of state a person
// or the service makes is an entry (who, when, what, about what, the details), and each entry's
// SHA-256 covers its own fields and the hash of the entry before it. An entry edited afterwards
// no longer matches its hash; one deleted leaves a gap in the sequence and breaks the next
// entry's link; the last ones deleted no longer reach the head the database records beside them.
// Pure: the database (daemon_db.hpp) stores the entries, this computes and checks the chain.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace imucal::daemon {

struct AuditEntry {
  std::int64_t seq = 0;   // 1, 2, 3, ... without gaps
  std::int64_t t_ms = 0;  // Unix milliseconds, UTC
  std::string actor;      // the user's name, or "imucald" for the service itself
  std::string action;     // "campaign.created", "campaign.command", "limits.replaced", ...
  std::string subject;    // what it is about: "campaign 7", "limits", "alarm 12", a certificate number
  std::string details_json;  // what changed: a JSON object (before and after, a reason)
  std::string prev_sha256;   // the entry before's sha256 (kAuditGenesis for the first)
  std::string sha256;        // audit_entry_sha256 of this entry
};

// The link of the first entry.
inline constexpr const char* kAuditGenesis = "0000000000000000000000000000000000000000000000000000000000000000";

// Hex SHA-256 of the entry's canonical JSON (signing::canonical_json of seq, t_ms, actor, action,
// subject, the parsed details and prev_sha256): what sha256 must be.
std::string audit_entry_sha256(const AuditEntry& entry);

// The entry after the last one (`last`: its seq and sha256; none for the first entry), linked to it
// and hashed: the one rule for appending, whichever database stores the chain.
struct AuditFields {
  std::int64_t t_ms = 0;
  std::string actor, action, subject, details_json;
};
AuditEntry next_audit_entry(const std::optional<std::pair<std::int64_t, std::string>>& last, AuditFields fields);

// The whole trail in order and the head the store recorded beside it, read together in one
// snapshot: read apart, an entry appended between the two reads looks like entries deleted at the
// end (the head past the last entry read).
struct AuditChain {
  std::vector<AuditEntry> entries;
  std::optional<std::pair<std::int64_t, std::string>> head;
};

struct AuditCheck {
  std::int64_t entries = 0;               // how many were read
  std::optional<std::int64_t> first_bad;  // the first entry that does not hold (its seq)
  std::string message;                    // what holds, or what is wrong with first_bad

  bool ok() const { return !first_bad.has_value(); }
};

// Checks entries in their order: each seq one more than the one before (from 1), each
// prev_sha256 the hash of the one before, each sha256 its own hash, and the last one the recorded
// head (seq and sha256) when there is one. Names the first entry that fails and why.
AuditCheck check_audit_chain(const std::vector<AuditEntry>& entries,
                             const std::optional<std::pair<std::int64_t, std::string>>& head);
inline AuditCheck check_audit_chain(const AuditChain& chain) { return check_audit_chain(chain.entries, chain.head); }

}  // namespace imucal::daemon
