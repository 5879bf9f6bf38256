#include "daemon/production/lab_users.hpp"

#include <algorithm>
#include <stdexcept>

#include "daemon/config/password_hash.hpp"

namespace imucal::daemon {

using nlohmann::json;

namespace {

constexpr std::size_t kMaxNameLength = 64;

bool configured(const std::vector<UserEntry>& users, const std::string& name) {
  return std::any_of(users.begin(), users.end(), [&](const UserEntry& u) { return u.name == name; });
}

void check_name(const std::string& name) {
  if (name.empty() || name.size() > kMaxNameLength)
    throw std::invalid_argument("an account's name must have 1 to " + std::to_string(kMaxNameLength) + " characters");
  for (const char c : name)
    if (static_cast<unsigned char>(c) < 0x21 || c == 0x7f)
      throw std::invalid_argument("an account's name may not hold spaces or control characters: '" + name + "'");
}

}  // namespace

json users_json(const std::vector<UserEntry>& configured_users, const std::vector<UserRow>& lab) {
  json out = json::array();
  for (const UserEntry& u : configured_users)
    out.push_back({{"name", u.name},
                   {"role", to_string(u.role)},
                   {"source", "configuration"},
                   {"password", !u.password_hash.empty()},
                   {"token", !u.token.empty()},
                   {"changed", nullptr},
                   {"changed_by", nullptr}});
  for (const UserRow& r : lab) {
    json entry = {{"name", r.name},          {"role", r.role},
                  {"source", "registry"},    {"password", !r.password_hash.empty()},
                  {"token", false},          {"changed", iso8601_utc(r.changed_ms)},
                  {"changed_by", r.changed_by}};
    if (configured(configured_users, r.name)) entry["shadowed"] = true;  // the configuration's wins here
    out.push_back(std::move(entry));
  }
  return {{"users", out}};
}

UserRow lab_user_from_request(const std::string& name, const json& body, const std::string& actor, std::int64_t now_ms) {
  check_name(name);
  if (!body.is_object()) throw std::invalid_argument("the account must be a JSON object {\"role\", \"password\"}");
  for (const auto& [key, value] : body.items())
    if (key != "role" && key != "password") throw std::invalid_argument("unknown field '" + key + "' (role, password)");
  const std::string role = body.value("role", "");
  if (role != "viewer" && role != "operator")
    throw std::invalid_argument("role must be \"viewer\" or \"operator\", not '" + role + "'");
  if (!body.contains("password") || !body.at("password").is_string())
    throw std::invalid_argument("password must be given, as text");
  const std::string password = body.at("password").get<std::string>();
  if (password.size() < kMinPasswordLength)
    throw std::invalid_argument("the password must have at least " + std::to_string(kMinPasswordLength) + " characters");
  return UserRow{name, role, hash_password(password), now_ms, actor};
}

std::vector<UserEntry> lab_user_entries(const std::vector<UserRow>& rows) {
  std::vector<UserEntry> out;
  for (const UserRow& r : rows)
    out.push_back(UserEntry{r.name, r.role == "operator" ? Role::Operator : Role::Viewer, r.password_hash, ""});
  return out;
}

}  // namespace imucal::daemon
