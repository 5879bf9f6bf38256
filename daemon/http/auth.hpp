// Who may do what: API tokens (`Authorization: Bearer`), users with passwords for the browser
// sign-in, and the sessions (cookie) it creates. Two roles: viewer (reads) and operator (reads and
// changes). When no operator credential is configured, a token is generated on the first start,
// kept in DATA_DIR/operator-token (mode 0600) and printed once.
#pragma once

#include <chrono>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "daemon/config/config.hpp"

namespace imucal::daemon {

struct Principal {
  std::string user;
  Role role = Role::Viewer;
  std::string via;  // "token" or "session"
  std::string session_id;  // the session's id when via == "session"
};

// 32 random bytes from the system's entropy source, as 64 hex digits.
std::string random_token_hex();
// Comparison whose time does not depend on where the strings differ.
bool constant_time_equal(std::string_view a, std::string_view b);

class Auth {
 public:
  Auth(const DaemonConfig& config, const std::string& data_dir);

  // The token generated on this start (print it once), or empty.
  const std::string& generated_token() const { return generated_token_; }
  const std::string& token_file() const { return token_file_; }

  std::optional<Principal> from_token(std::string_view token) const;
  std::optional<Principal> from_session(std::string_view session_id);

  struct Login {
    int status = 200;  // 200, 401, 429
    std::string error;
    std::string session_id;
    Principal principal;
  };
  // Failed sign-ins are throttled per client address (`client`, empty in-process) and per user
  // name, never globally: one client guessing locks out only itself (and, past a larger count
  // from any clients, the name it guesses at).
  Login login_password(const std::string& user, const std::string& password, const std::string& client = "");
  Login login_token(const std::string& token, const std::string& client = "");
  void logout(std::string_view session_id);
  // Whether the session still exists and has not expired; unlike from_session() this is not a
  // use (an open WebSocket does not keep its session alive).
  bool session_alive(std::string_view session_id);
  double idle_timeout_s() const { return idle_timeout_s_; }

  // The lab's accounts (registry.hpp users, issue 38): they sign in with a password as the
  // configured users do; a configured user of the same name wins. Read at a sign-in, at most
  // every kLabUsersFresh (an account put on another stand signs in here within it); a source that
  // fails keeps the accounts last read, and the configured users sign in whatever it does. One
  // sign-in at a time reads; the others meanwhile use the accounts read before, without waiting.
  // A lab account's session ends when the account is removed or its password or role changed, on
  // any stand (seen within kLabUsersFresh of a request or a live page's check).
  using LabUsers = std::function<std::vector<UserEntry>()>;
  static constexpr std::chrono::seconds kLabUsersFresh{5};
  void set_lab_users(LabUsers source);

 private:
  // The configured users and the lab's accounts that may sign in as `user` with a password.
  struct Candidate {
    UserEntry user;
    bool lab = false;  // a lab account (else the configuration's)
  };
  std::vector<Candidate> password_candidates(const std::string& user);
  // The lab's accounts, read again when older than kLabUsersFresh; none without a source.
  std::vector<UserEntry> lab_users();
  // Whether the lab account `p` signed in as is still there with this password hash and role.
  bool lab_account_holds(const Principal& p, const std::string& password_hash);
  struct Session {
    Principal principal;
    std::chrono::steady_clock::time_point last_use;
    std::string lab_password_hash;  // a lab account's session: its hash at the sign-in (else empty)
  };
  Login start_session(const Principal& p, const std::string& lab_password_hash = {});
  // Whether the failures counted under these keys (within the last minute) reach their limits;
  // mutex_ held.
  bool throttled(const std::vector<std::pair<std::string, int>>& keys_and_limits);
  void failed(const std::vector<std::pair<std::string, int>>& keys_and_limits);

  struct TokenEntry {
    std::string token;
    Principal principal;
  };
  std::vector<TokenEntry> tokens_;
  std::vector<UserEntry> users_;
  LabUsers lab_users_;
  std::vector<UserEntry> lab_users_read_;  // under lab_mutex_
  std::optional<std::chrono::steady_clock::time_point> lab_users_at_;
  bool lab_users_reading_ = false;  // a caller is reading lab_users_ (outside lab_mutex_)
  bool lab_users_failing_ = false;  // the last read failed
  std::mutex lab_mutex_;  // apart from mutex_: reading the registry must not hold up the sessions
  std::string generated_token_, token_file_;
  double idle_timeout_s_;

  std::mutex mutex_;
  std::map<std::string, Session, std::less<>> sessions_;
  // Failed sign-ins of the last minute by "client ADDRESS" and "user NAME".
  std::map<std::string, std::deque<std::chrono::steady_clock::time_point>, std::less<>> failures_;
};

}  // namespace imucal::daemon
