#include "daemon/http/auth.hpp"

#include <sys/stat.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <random>

#include <spdlog/spdlog.h>

#include "daemon/config/password_hash.hpp"

namespace imucal::daemon {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {
constexpr std::size_t kMaxSessions = 1000;
constexpr int kMaxFailuresPerClientPerMinute = 5;
// Higher than a client's: guesses at one name spread over many addresses are throttled too, while
// one client's five do not lock that user out for everyone else.
constexpr int kMaxFailuresPerUserPerMinute = 20;
constexpr std::size_t kMaxThrottleKeys = 10000;  // beyond: the stale keys are dropped
}  // namespace

std::string random_token_hex() {
  std::random_device entropy;  // /dev/urandom (or RDRAND) with libstdc++ on Linux
  static constexpr char kHex[] = "0123456789abcdef";
  std::string out;
  out.reserve(64);
  for (int i = 0; i < 8; ++i) {
    const auto word = static_cast<std::uint32_t>(entropy());
    for (int nibble = 0; nibble < 8; ++nibble) out.push_back(kHex[(word >> (4 * nibble)) & 0xF]);
  }
  return out;
}

bool constant_time_equal(std::string_view a, std::string_view b) {
  unsigned diff = a.size() == b.size() ? 0u : 1u;
  const std::size_t n = std::max(a.size(), b.size());
  for (std::size_t i = 0; i < n; ++i) {
    const auto x = static_cast<unsigned char>(i < a.size() ? a[i] : 0);
    const auto y = static_cast<unsigned char>(i < b.size() ? b[i] : 0);
    diff |= static_cast<unsigned>(x ^ y);
  }
  return diff == 0;
}

Auth::Auth(const DaemonConfig& config, const std::string& data_dir)
    : users_(config.users), idle_timeout_s_(config.http.session_idle_s) {
  bool have_operator = false;
  if (!config.operator_token.empty()) {
    tokens_.push_back({config.operator_token, {"operator", Role::Operator, "token", ""}});
    have_operator = true;
  }
  for (const UserEntry& u : config.users) {
    if (!u.token.empty()) tokens_.push_back({u.token, {u.name, u.role, "token", ""}});
    if (u.role == Role::Operator && (!u.token.empty() || !u.password_hash.empty())) have_operator = true;
  }
  if (!have_operator) {
    // Nobody could ever change anything: use (or make) the generated operator token.
    token_file_ = (fs::path(data_dir) / "operator-token").string();
    std::string token;
    if (std::ifstream in(token_file_); in) std::getline(in, token);
    if (token.size() < 16) {
      token = random_token_hex();
      const mode_t old_mask = ::umask(077);  // the file is a credential: owner only
      std::ofstream out(token_file_, std::ios::trunc);
      ::umask(old_mask);
      if (!out) throw ConfigError("cannot write the operator token file " + token_file_);
      out << token << "\n";
      out.close();
      fs::permissions(token_file_, fs::perms::owner_read | fs::perms::owner_write, fs::perm_options::replace);
      generated_token_ = token;
    }
    tokens_.push_back({token, {"operator", Role::Operator, "token", ""}});
  }
}

std::optional<Principal> Auth::from_token(std::string_view token) const {
  if (token.empty()) return std::nullopt;
  std::optional<Principal> found;
  // Compare against every token so that the time taken says nothing about which matched.
  for (const TokenEntry& t : tokens_)
    if (constant_time_equal(t.token, token) && !found) found = t.principal;
  return found;
}

std::optional<Principal> Auth::from_session(std::string_view session_id) {
  if (session_id.empty()) return std::nullopt;
  Principal p;
  std::string lab_hash;
  {
    std::lock_guard lock(mutex_);
    const auto it = sessions_.find(session_id);
    if (it == sessions_.end()) return std::nullopt;
    const auto now = Clock::now();
    if (std::chrono::duration<double>(now - it->second.last_use).count() > idle_timeout_s_) {
      sessions_.erase(it);
      return std::nullopt;
    }
    it->second.last_use = now;
    p = it->second.principal;
    lab_hash = it->second.lab_password_hash;
  }
  if (!lab_hash.empty() && !lab_account_holds(p, lab_hash)) {
    logout(session_id);
    return std::nullopt;
  }
  p.via = "session";
  p.session_id = std::string(session_id);
  return p;
}

bool Auth::throttled(const std::vector<std::pair<std::string, int>>& keys_and_limits) {
  const auto now = Clock::now();
  for (const auto& [key, limit] : keys_and_limits) {
    const auto it = failures_.find(key);
    if (it == failures_.end()) continue;
    auto& times = it->second;
    while (!times.empty() && now - times.front() > std::chrono::minutes(1)) times.pop_front();
    if (static_cast<int>(times.size()) >= limit) return true;
  }
  return false;
}

void Auth::failed(const std::vector<std::pair<std::string, int>>& keys_and_limits) {
  const auto now = Clock::now();
  if (failures_.size() >= kMaxThrottleKeys)
    std::erase_if(failures_, [&](const auto& entry) {
      return entry.second.empty() || now - entry.second.back() > std::chrono::minutes(1);
    });
  for (const auto& [key, limit] : keys_and_limits) {
    auto& times = failures_[key];
    times.push_back(now);
    while (static_cast<int>(times.size()) > limit) times.pop_front();  // the limit is all that is asked
  }
}

Auth::Login Auth::start_session(const Principal& p, const std::string& lab_password_hash) {
  const auto now = Clock::now();
  // Drop expired sessions, and the oldest when there are too many.
  for (auto it = sessions_.begin(); it != sessions_.end();) {
    if (std::chrono::duration<double>(now - it->second.last_use).count() > idle_timeout_s_) {
      it = sessions_.erase(it);
    } else {
      ++it;
    }
  }
  if (sessions_.size() >= kMaxSessions) {
    auto oldest = sessions_.begin();
    for (auto it = sessions_.begin(); it != sessions_.end(); ++it)
      if (it->second.last_use < oldest->second.last_use) oldest = it;
    sessions_.erase(oldest);
  }
  Login login;
  login.session_id = random_token_hex();
  login.principal = p;
  login.principal.via = "session";
  sessions_[login.session_id] = {login.principal, now, lab_password_hash};
  return login;
}

namespace {
// A hash no password matches in practice, verified for unknown users (made once, lazily).
const std::string& unknown_user_hash() {
  static const std::string hash = hash_password("imucal: no such user, a fixed random-looking text 7f3a9c");
  return hash;
}
}  // namespace

void Auth::set_lab_users(LabUsers source) {
  std::lock_guard lock(lab_mutex_);
  lab_users_ = std::move(source);
  lab_users_at_.reset();
}

std::vector<Auth::Candidate> Auth::password_candidates(const std::string& user) {
  std::vector<Candidate> out;
  for (const UserEntry& u : users_)  // fixed at start: read without a lock
    if (!u.password_hash.empty() && constant_time_equal(u.name, user)) out.push_back({u, false});
  if (!out.empty()) return out;  // the configuration wins
  for (const UserEntry& u : lab_users())
    if (!u.password_hash.empty() && constant_time_equal(u.name, user)) out.push_back({u, true});
  return out;
}

std::vector<UserEntry> Auth::lab_users() {
  // One caller reads the registry, outside the lock (a server away holds it up to its connect
  // timeout); the others meanwhile take the accounts read before instead of queuing behind it.
  LabUsers source;
  {
    std::lock_guard lock(lab_mutex_);
    if (!lab_users_) return {};
    const auto now = Clock::now();
    if (!lab_users_reading_ && (!lab_users_at_ || now - *lab_users_at_ >= kLabUsersFresh)) {
      lab_users_at_ = now;
      lab_users_reading_ = true;
      source = lab_users_;
    }
  }
  if (source) {
    std::optional<std::vector<UserEntry>> fresh;
    std::string failure;
    try {
      fresh = source();
    } catch (const std::exception& e) {
      failure = e.what();
    }
    std::lock_guard lock(lab_mutex_);
    lab_users_reading_ = false;
    if (fresh) lab_users_read_ = std::move(*fresh);
    if (!failure.empty() && !lab_users_failing_)  // once per outage, not at every read
      spdlog::warn("the lab's accounts could not be read ({}); the ones read before sign in", failure);
    lab_users_failing_ = !failure.empty();
  }
  std::lock_guard lock(lab_mutex_);
  return lab_users_read_;
}

bool Auth::lab_account_holds(const Principal& p, const std::string& password_hash) {
  const std::vector<UserEntry> accounts = lab_users();
  return std::any_of(accounts.begin(), accounts.end(), [&](const UserEntry& u) {
    return u.name == p.user && u.role == p.role && u.password_hash == password_hash;
  });
}

Auth::Login Auth::login_password(const std::string& user, const std::string& password, const std::string& client) {
  const std::vector<std::pair<std::string, int>> keys = {{"client " + client, kMaxFailuresPerClientPerMinute},
                                                         {"user " + user, kMaxFailuresPerUserPerMinute}};
  {
    std::lock_guard lock(mutex_);
    if (throttled(keys)) return {429, "too many failed sign-ins; wait a minute", {}, {}};
  }
  const std::vector<Candidate> candidates = password_candidates(user);
  // Outside the lock: a hash takes a fraction of a second by design, other requests go on.
  // An unknown user costs a hash too, so the time does not tell which users exist.
  const Candidate* match = nullptr;
  for (const Candidate& c : candidates)
    if (match == nullptr && verify_password(c.user.password_hash, password)) match = &c;
  if (candidates.empty()) (void)verify_password(unknown_user_hash(), password);
  std::lock_guard lock(mutex_);
  if (match == nullptr) {
    failed(keys);
    return {401, "wrong user or password", {}, {}};
  }
  return start_session({match->user.name, match->user.role, "session", ""},
                       match->lab ? match->user.password_hash : std::string());
}

Auth::Login Auth::login_token(const std::string& token, const std::string& client) {
  const std::vector<std::pair<std::string, int>> keys = {{"client " + client, kMaxFailuresPerClientPerMinute}};
  std::lock_guard lock(mutex_);
  if (throttled(keys)) return {429, "too many failed sign-ins; wait a minute", {}, {}};
  const auto p = from_token(token);
  if (!p) {
    failed(keys);
    return {401, "unknown token", {}, {}};
  }
  return start_session(*p);
}

bool Auth::session_alive(std::string_view session_id) {
  Principal p;
  std::string lab_hash;
  {
    std::lock_guard lock(mutex_);
    const auto it = sessions_.find(session_id);
    if (it == sessions_.end()) return false;
    if (std::chrono::duration<double>(Clock::now() - it->second.last_use).count() > idle_timeout_s_) {
      sessions_.erase(it);
      return false;
    }
    p = it->second.principal;
    lab_hash = it->second.lab_password_hash;
  }
  if (!lab_hash.empty() && !lab_account_holds(p, lab_hash)) {
    logout(session_id);
    return false;
  }
  return true;
}

void Auth::logout(std::string_view session_id) {
  std::lock_guard lock(mutex_);
  const auto it = sessions_.find(session_id);
  if (it != sessions_.end()) sessions_.erase(it);
}

}  // namespace imucal::daemon
