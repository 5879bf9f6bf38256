// The lab's accounts (issue 38, deliverable 1; registry.hpp put_user): what GET /api/users shows
// and PUT /api/users/{name} makes. They sign in with a password on every stand of the lab (tokens
// stay in each stand's configuration); a stand's configured user of the same name wins there.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "daemon/config/config.hpp"
#include "daemon/db/daemon_db.hpp"

namespace imucal::daemon {

// {"users": [{"name", "role", "source": "configuration" | "registry", "password": bool,
// "token": bool, "changed", "changed_by"}]}: the configured users first, then the lab's accounts
// the configuration does not name (one a configured user shadows says "shadowed": true), by name.
// No secret, not even a hash.
nlohmann::json users_json(const std::vector<UserEntry>& configured, const std::vector<UserRow>& lab);

// An account from PUT's body {"role": "viewer" | "operator", "password": "..." (kMinPasswordLength
// characters at least, as `imucal passwd` takes)} by `actor` at
// `now_ms`, its password hashed (Argon2id, as `imucal passwd`). Throws std::invalid_argument naming
// what is wrong: a name that is empty, too long or not printable; an unknown role; a missing or
// short password; an unknown field.
UserRow lab_user_from_request(const std::string& name, const nlohmann::json& body, const std::string& actor,
                              std::int64_t now_ms);

// The accounts as the sign-in takes them (http/auth.hpp set_lab_users).
std::vector<UserEntry> lab_user_entries(const std::vector<UserRow>& rows);

}  // namespace imucal::daemon
