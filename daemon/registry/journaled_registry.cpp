#include "daemon/registry/journaled_registry.hpp"

#include <cstring>
#include <deque>
#include <filesystem>
#include <fstream>
#include <random>
#include <type_traits>
#include <utility>

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include "daemon/registry/calibrations.hpp"
#include "daemon/registry/postgres_registry.hpp"
#include "storage/durable_file.hpp"

namespace imucal::daemon {

namespace {

using nlohmann::json;
using storage::pg::PgError;

// A failure of the journal's disk. Connection lost, as the server's absence it stands in for: a
// caller that keeps writes to repeat them (the sequencer's WriteQueue) keeps this one too.
[[noreturn]] void journal_failure(const std::string& path, const std::string& doing, int error) {
  throw PgError("registry: the PostgreSQL server is unreachable and its journal " + path + " cannot be " + doing +
                    ": " + std::strerror(error),
                "", true);
}

// A write of the journal's file (storage/durable_file.hpp), its failure the server's absence's.
void durably(const std::string& path, const char* doing, const std::function<void()>& write) {
  try {
    write();
  } catch (const storage::FileError& e) {
    journal_failure(path, doing, e.error());
  }
}

// A journal's id: a journal whose file was lost starts numbering again under another id, and its
// keys never meet the ones the server recorded for the first.
std::string new_journal_id() {
  std::random_device random;
  std::mt19937_64 bits((static_cast<std::uint64_t>(random()) << 32U) ^ random() ^
                       static_cast<std::uint64_t>(std::chrono::system_clock::now().time_since_epoch().count()));
  char text[17];
  std::snprintf(text, sizeof text, "%016llx", static_cast<unsigned long long>(bits()));
  return text;
}

json optional_json(const std::optional<std::string>& value) { return value ? json(*value) : json(nullptr); }

std::optional<std::string> optional_text(const json& value) {
  if (value.is_null()) return std::nullopt;
  return value.get<std::string>();
}

json issued_json(const IssuedCertificateRow& r) {
  return {{"write", "issued"},           {"sequence", r.sequence},
          {"number", r.number},          {"campaign_id", r.campaign_id},
          {"issued_ms", r.issued_ms},    {"content_json", r.content_json},
          {"content_sha256", r.content_sha256}, {"signed_json", optional_json(r.signed_json)},
          {"supersedes", optional_json(r.supersedes)}, {"reason", r.reason}};
}

IssuedCertificateRow issued_from(const json& j) {
  IssuedCertificateRow r;
  r.sequence = j.at("sequence").get<std::int64_t>();
  r.number = j.at("number").get<std::string>();
  r.campaign_id = j.at("campaign_id").get<std::int64_t>();
  r.issued_ms = j.at("issued_ms").get<std::int64_t>();
  r.content_json = j.at("content_json").get<std::string>();
  r.content_sha256 = j.at("content_sha256").get<std::string>();
  r.signed_json = optional_text(j.at("signed_json"));
  r.supersedes = optional_text(j.at("supersedes"));
  r.reason = j.at("reason").get<std::string>();
  return r;
}

json stand_json(const StandRow& r) {
  return {{"write", "stand"},          {"name", r.name},
          {"bench", r.bench},          {"url", r.url},
          {"version", r.version},      {"heartbeat_ms", r.heartbeat_ms},
          {"registered_ms", r.registered_ms}, {"last_seen_ms", r.last_seen_ms},
          {"state_json", r.state_json}};
}

StandRow stand_from(const json& j) {
  return StandRow{j.at("name").get<std::string>(),          j.at("bench").get<std::string>(),
                  j.at("url").get<std::string>(),           j.at("version").get<std::string>(),
                  j.at("heartbeat_ms").get<std::int64_t>(), j.at("registered_ms").get<std::int64_t>(),
                  j.at("last_seen_ms").get<std::int64_t>(), j.at("state_json").get<std::string>()};
}

// One journaled write applied to the server, as the call that journaled it would have.
void apply_journaled(PostgresRegistry& server, const json& j) {
  const std::string write = j.at("write").get<std::string>();
  if (write == "certificate") {
    server.insert_certificate({j.at("campaign_id").get<std::int64_t>(), j.at("number").get<std::string>(),
                               j.at("sequence").get<std::int64_t>(), j.at("issued_ms").get<std::int64_t>(),
                               j.at("bench_json").get<std::string>()});
  } else if (write == "issued") {
    server.insert_issued(issued_from(j));
  } else if (write == "issued_page") {
    (void)server.insert_issued_page({j.at("number").get<std::string>(), j.at("html").get<std::string>(),
                                     j.at("sha256").get<std::string>(), j.at("stored_ms").get<std::int64_t>(),
                                     j.at("stored_by").get<std::string>()});
  } else if (write == "overdue_override") {
    server.insert_overdue_override({j.at("campaign_id").get<std::int64_t>(), j.at("t_ms").get<std::int64_t>(),
                                    j.at("by").get<std::string>(), j.at("reason").get<std::string>(),
                                    j.at("instruments_json").get<std::string>(), j.at("text").get<std::string>()});
  } else if (write == "overdue_override_removed") {
    server.remove_overdue_override(j.at("campaign_id").get<std::int64_t>());
  } else if (write == "calibration") {
    server.record_calibration(campaign_row_from_json(j.at("row").get<std::string>()));
  } else if (write == "limits") {
    server.put_limits_document(j.at("document_json").get<std::string>(), j.at("actor").get<std::string>());
  } else if (write == "audit") {
    // Chained now, after the entries before it, with the time it happened.
    (void)server.append_audit(j.at("actor").get<std::string>(), j.at("action").get<std::string>(),
                              j.at("subject").get<std::string>(), j.at("details_json").get<std::string>(),
                              j.at("t_ms").get<std::int64_t>());
  } else if (write == "stand") {
    server.register_stand(stand_from(j));
  } else if (write == "user") {
    server.put_user({j.at("name").get<std::string>(), j.at("role").get<std::string>(),
                     j.at("password_hash").get<std::string>(), j.at("changed_ms").get<std::int64_t>(),
                     j.at("changed_by").get<std::string>()});
  } else if (write == "user_removed") {
    (void)server.remove_user(j.at("name").get<std::string>());
  } else {
    throw std::invalid_argument("unknown journaled write '" + write + "'");
  }
}

// Entries replayed between two rewrites of the journal: a crash replays at most these again (and
// their keys skip them), while a long journal is not rewritten once per entry.
constexpr std::size_t kTrimEvery = 64;

}  // namespace

// The journal's file and the writes waiting in it (journaled_registry.hpp says its format).
class RegistryJournal {
 public:
  explicit RegistryJournal(std::string path) : path_(std::move(path)) {
    if (std::filesystem::exists(path_)) {
      load();
    } else {
      id_ = new_journal_id();
      trim();
    }
  }

  const std::string& id() const { return id_; }
  bool empty() const { return entries_.empty(); }
  std::int64_t size() const { return static_cast<std::int64_t>(entries_.size()); }
  const json& front() const { return entries_.front(); }
  void pop_front() { entries_.pop_front(); }

  // Numbers `entry`, adds it at the end and on the disk; its number.
  std::int64_t append(json entry) {
    entry["seq"] = next_seq_;
    durably(path_, "written", [&] { storage::append_durably(path_, entry.dump() + "\n"); });
    entries_.push_back(std::move(entry));
    return next_seq_++;
  }

  // The file rewritten with the writes still waiting (a crash leaves the old file or the new).
  void trim() {
    std::string text = json{{"imucal_registry_journal", 1}, {"id", id_}, {"next_seq", next_seq_}}.dump() + "\n";
    for (const json& entry : entries_) text += entry.dump() + "\n";
    durably(path_, "replaced", [&] { storage::replace_file_durably(path_, text, /*owner_only=*/true); });
  }

  // trim() whose failure is no caller's: the writes are applied (the server has them and their
  // keys), and a file not trimmed is only replayed again, with nothing applied twice.
  void trim_or_say_why() noexcept {
    try {
      trim();
    } catch (const std::exception& e) {
      spdlog::error("registry: the journal's applied writes stay in it for now: {}", e.what());
    }
  }

  // A write the server refused at replay (or a line that is no write): kept for the operator.
  void set_aside(const json& entry, const std::string& why) {
    spdlog::error("registry: journaled write refused by the PostgreSQL server, kept in {}: {}: {}", refused_path(),
                  entry.dump(), why);
    const std::string path = refused_path();
    durably(path, "written", [&] { storage::append_durably(path, json{{"entry", entry}, {"refused", why}}.dump() + "\n"); });
  }

 private:
  std::string refused_path() const {
    const std::filesystem::path p(path_);
    return (p.parent_path() / (p.stem().string() + "-refused.jsonl")).string();
  }

  void load() {
    std::ifstream in(path_);
    std::string line;
    json header;
    if (std::getline(in, line)) header = json::parse(line, nullptr, false);
    if (!header.is_object() || !header.contains("id") || !header.contains("next_seq"))
      throw storage::StorageError("registry: the journal " + path_ +
                                  " has no readable header (its first line): move it aside after reading it");
    id_ = header.at("id").get<std::string>();
    next_seq_ = header.at("next_seq").get<std::int64_t>();
    while (std::getline(in, line)) {
      if (line.empty()) continue;
      json entry = json::parse(line, nullptr, false);
      // A line a crash cut short was never acknowledged to its caller.
      if (!entry.is_object() || !entry.contains("seq") || !entry.at("seq").is_number_integer()) {
        set_aside(json(line), "not a journaled write (a line cut short by a crash?)");
        continue;
      }
      next_seq_ = std::max(next_seq_, entry.at("seq").get<std::int64_t>() + 1);
      entries_.push_back(std::move(entry));
    }
  }

  std::string path_;
  std::string id_;
  std::int64_t next_seq_ = 1;
  std::deque<json> entries_;
};

JournaledRegistry::JournaledRegistry(Connect connect, std::string journal_path, Options options)
    : connect_(std::move(connect)),
      journal_path_(std::move(journal_path)),
      options_(std::move(options)),
      journal_(std::make_unique<RegistryJournal>(journal_path_)),
      direct_journal_(journal_->id() + "/direct/" + new_journal_id()) {
  pending_ = journal_->size();
  if (pending_ > 0)
    spdlog::warn("registry: {} writes wait in {} from before; they are replayed once the PostgreSQL server answers",
                 pending_.load(), journal_path_);
  (void)retry();  // the server asked now: GET /api/status says at once whether it answers
  if (options_.retry_every.count() > 0) retry_thread_ = std::thread([this] { retry_loop(); });
}

JournaledRegistry::~JournaledRegistry() {
  {
    std::lock_guard lock(stop_mutex_);
    stopping_ = true;
  }
  stop_cv_.notify_all();
  if (retry_thread_.joinable()) retry_thread_.join();
}

void JournaledRegistry::retry_loop() {
  std::unique_lock lock(stop_mutex_);
  while (!stop_cv_.wait_for(lock, options_.retry_every, [this] { return stopping_; })) {
    if (reachable_ && pending_ == 0) continue;
    lock.unlock();
    try {
      (void)retry();
    } catch (const std::exception& e) {
      spdlog::error("registry: retrying the PostgreSQL server: {}", e.what());
    }
    lock.lock();
  }
}

bool JournaledRegistry::retry() {
  std::lock_guard lock(mutex_);
  if (!ready(true)) return false;
  if (reachable_) return true;
  // Nothing was replayed, so nothing has asked the server yet: a question it must answer.
  return asked([](PostgresRegistry& server) { (void)server.schema_version(); });
}

bool JournaledRegistry::asked(const Call& call) {
  try {
    call(*server_);
    answered();
    return true;
  } catch (const PgError& e) {
    if (!e.connection_lost()) throw;
    went_away(e.what());
    return false;
  }
}

void JournaledRegistry::went_away(const std::string& why) {
  if (reachable_ || last_failure_.empty())
    spdlog::warn("registry: the PostgreSQL server is unreachable ({}); the registry's writes wait in {} until it answers",
                 why, journal_path_);
  reachable_ = false;
  last_failure_ = why;
  last_attempt_ = std::chrono::steady_clock::now();
}

void JournaledRegistry::answered() {
  if (!reachable_) spdlog::info("registry: the PostgreSQL server answers");
  reachable_ = true;
}

PostgresRegistry* JournaledRegistry::connected() {
  if (server_) return server_.get();
  try {
    server_ = connect_();
  } catch (const PgError& e) {
    if (!e.connection_lost()) throw;
    went_away(e.what());
    return nullptr;
  }
  return server_.get();
}

// Whether the server may be asked now: connected, and every journaled write before replayed.
// While it is away it is tried again no more often than call_retry_interval (unless `force`).
bool JournaledRegistry::ready(bool force) {
  const auto now = std::chrono::steady_clock::now();
  if (!force && !reachable_ && now - last_attempt_ < options_.call_retry_interval) return false;
  last_attempt_ = now;
  if (connected() == nullptr) return false;
  return replay();
}

bool JournaledRegistry::replay() {
  if (journal_->empty()) return true;
  const std::int64_t waiting = journal_->size();
  std::size_t since_trim = 0;
  bool complete = true;
  while (!journal_->empty()) {
    if (!replay_one(journal_->front())) {
      complete = false;
      break;
    }
    journal_->pop_front();
    pending_ = journal_->size();
    if (++since_trim == kTrimEvery) {
      journal_->trim_or_say_why();
      since_trim = 0;
    }
  }
  journal_->trim_or_say_why();
  if (complete) spdlog::info("registry: the {} journaled writes are replayed on the PostgreSQL server", waiting);
  return complete;
}

// False when the server went away (the write stays first in the journal).
bool JournaledRegistry::replay_one(const json& entry) {
  try {
    const std::int64_t seq = entry.at("seq").get<std::int64_t>();
    // A write tried at once carries the key it was tried with (write()); the others their number here.
    const json key = entry.value("key", json{{"journal", journal_->id()}, {"seq", seq}});
    if (!server_->apply_once(key.at("journal").get<std::string>(), key.at("seq").get<std::int64_t>(),
                             [this, &entry] { apply_journaled(*server_, entry); }))
      spdlog::info("registry: journaled write {} was applied before (its replay interrupted, or its reply lost): not again",
                   seq);
    answered();
  } catch (const PgError& e) {
    if (e.connection_lost()) {
      went_away(e.what());
      return false;
    }
    journal_->set_aside(entry, e.what());
  } catch (const std::exception& e) {  // a malformed entry: no write to apply
    journal_->set_aside(entry, e.what());
  }
  return true;
}

void JournaledRegistry::write(const json& entry, const Call& apply) {
  // Tried at once with a key of its own, committed with it (apply_once): when the connection
  // breaks after the server committed and before its reply arrived, the write goes to the journal
  // with that key, and its replay finds it applied (before, such a write was applied twice: an
  // audit entry doubled). The keys' journal is this process's own, so a number is never reused.
  const std::int64_t key_seq = ++direct_writes_;
  const auto keyed = [&](PostgresRegistry& r) {
    (void)r.apply_once(direct_journal_, key_seq, [&] { apply(r); });
    if (options_.after_direct_write) options_.after_direct_write();
  };
  if (ready(false) && asked(keyed)) return;
  json journaled = entry;
  journaled["key"] = {{"journal", direct_journal_}, {"seq", key_seq}};
  const std::int64_t seq = journal_->append(journaled);
  pending_ = journal_->size();
  spdlog::info("registry: {} journaled as write {} ({} waiting for the PostgreSQL server)",
               entry.at("write").get<std::string>(), seq, pending_.load());
}

void JournaledRegistry::read(const char* what, const Call& query) {
  if (ready(false) && asked(query)) return;
  throw PgError("registry: " + std::string(what) +
                    " needs the lab's PostgreSQL server (registry.postgresql), which is unreachable (" + last_failure_ +
                    "); " + std::to_string(pending_.load()) + " writes of this stand wait in " + journal_path_ +
                    " to be replayed when it answers",
                "", true);
}

template <class Query>
auto JournaledRegistry::answer(const char* what, const Query& query) {
  std::lock_guard lock(mutex_);
  std::invoke_result_t<const Query&, PostgresRegistry&> out{};
  read(what, [&](PostgresRegistry& r) { out = query(r); });
  return out;
}

std::int64_t JournaledRegistry::next_certificate_sequence() {
  return answer("a certificate number", [&](PostgresRegistry& r) { return r.next_certificate_sequence(); });
}

Registry::CertificateNumber JournaledRegistry::take_certificate_number() {
  return answer("a certificate number", [&](PostgresRegistry& r) { return r.take_certificate_number(); });
}

std::int64_t JournaledRegistry::max_certificate_sequence() {
  return answer("the highest certificate number", [&](PostgresRegistry& r) { return r.max_certificate_sequence(); });
}

std::optional<CertificateRow> JournaledRegistry::certificate(std::int64_t campaign_id) {
  return answer("a campaign's certificate number", [&](PostgresRegistry& r) { return r.certificate(campaign_id); });
}

void JournaledRegistry::insert_certificate(const CertificateRow& row) {
  std::lock_guard lock(mutex_);
  write({{"write", "certificate"}, {"campaign_id", row.campaign_id}, {"number", row.number},
         {"sequence", row.sequence}, {"issued_ms", row.issued_ms}, {"bench_json", row.bench_json}},
        [&](PostgresRegistry& r) { r.insert_certificate(row); });
}

void JournaledRegistry::insert_issued(const IssuedCertificateRow& row) {
  std::lock_guard lock(mutex_);
  write(issued_json(row), [&](PostgresRegistry& r) { r.insert_issued(row); });
}

std::optional<IssuedCertificateRow> JournaledRegistry::issued(const std::string& number) {
  return answer("an issued certificate", [&](PostgresRegistry& r) { return r.issued(number); });
}

std::optional<IssuedCertificateRow> JournaledRegistry::current_issued(std::int64_t campaign_id) {
  return answer("a campaign's certificate", [&](PostgresRegistry& r) { return r.current_issued(campaign_id); });
}

std::vector<IssuedCertificateRow> JournaledRegistry::issued_history(std::int64_t campaign_id) {
  return answer("a campaign's certificates", [&](PostgresRegistry& r) { return r.issued_history(campaign_id); });
}

std::vector<std::int64_t> JournaledRegistry::campaigns_with_issued() {
  return answer("the campaigns with certificates", [&](PostgresRegistry& r) { return r.campaigns_with_issued(); });
}

bool JournaledRegistry::insert_issued_page(const IssuedPageRow& row) {
  std::lock_guard lock(mutex_);
  bool stored = true;
  write({{"write", "issued_page"}, {"number", row.number}, {"html", row.html}, {"sha256", row.sha256},
         {"stored_ms", row.stored_ms}, {"stored_by", row.stored_by}},
        [&](PostgresRegistry& r) { stored = r.insert_issued_page(row); });
  return stored;
}

std::optional<IssuedPageRow> JournaledRegistry::issued_page(const std::string& number, bool with_html) {
  return answer("a certificate's page", [&](PostgresRegistry& r) { return r.issued_page(number, with_html); });
}

void JournaledRegistry::insert_overdue_override(const OverdueOverrideRow& row) {
  std::lock_guard lock(mutex_);
  write({{"write", "overdue_override"}, {"campaign_id", row.campaign_id}, {"t_ms", row.t_ms}, {"by", row.by},
         {"reason", row.reason}, {"instruments_json", row.instruments_json}, {"text", row.text}},
        [&](PostgresRegistry& r) { r.insert_overdue_override(row); });
}

void JournaledRegistry::remove_overdue_override(std::int64_t campaign_id) {
  std::lock_guard lock(mutex_);
  write({{"write", "overdue_override_removed"}, {"campaign_id", campaign_id}},
        [&](PostgresRegistry& r) { r.remove_overdue_override(campaign_id); });
}

std::optional<OverdueOverrideRow> JournaledRegistry::overdue_override(std::int64_t campaign_id) {
  return answer("a campaign's overdue override", [&](PostgresRegistry& r) { return r.overdue_override(campaign_id); });
}

AuditEntry JournaledRegistry::append_audit(const std::string& actor, const std::string& action,
                                           const std::string& subject, const std::string& details_json,
                                           std::optional<std::int64_t> t_ms) {
  std::lock_guard lock(mutex_);
  // The time is taken now: a journaled entry keeps the time it happened, not the time of its replay.
  AuditEntry out{0, t_ms.value_or(now_unix_ms()), actor, action, subject, details_json, "", ""};
  write({{"write", "audit"}, {"t_ms", out.t_ms}, {"actor", actor}, {"action", action}, {"subject", subject},
         {"details_json", details_json}},
        [&](PostgresRegistry& r) { out = r.append_audit(actor, action, subject, details_json, out.t_ms); });
  return out;
}

std::vector<AuditEntry> JournaledRegistry::audit_entries(const AuditQuery& query) {
  return answer("the audit trail", [&](PostgresRegistry& r) { return r.audit_entries(query); });
}

AuditChain JournaledRegistry::audit_chain() {
  return answer("the audit trail", [&](PostgresRegistry& r) { return r.audit_chain(); });
}

// ---- Stands (issue 38, the lab overview) ----

void JournaledRegistry::register_stand(const StandRow& row) {
  std::lock_guard lock(mutex_);
  write(stand_json(row), [&](PostgresRegistry& r) { r.register_stand(row); });
}

// Not journaled (journaled_registry.hpp): with the server away the state is dropped, and true
// said, as the stand's registration waits in the journal and arrives before the next state.
bool JournaledRegistry::report_stand_state(const std::string& name, const std::string& state_json,
                                           std::int64_t t_ms) {
  std::lock_guard lock(mutex_);
  bool known = true;
  if (ready(false)) (void)asked([&](PostgresRegistry& r) { known = r.report_stand_state(name, state_json, t_ms); });
  return known;
}

std::vector<StandRow> JournaledRegistry::stands() {
  return answer("the lab's stands", [&](PostgresRegistry& r) { return r.stands(); });
}

void JournaledRegistry::put_user(const UserRow& row) {
  std::lock_guard lock(mutex_);
  write({{"write", "user"}, {"name", row.name}, {"role", row.role}, {"password_hash", row.password_hash},
         {"changed_ms", row.changed_ms}, {"changed_by", row.changed_by}},
        [&](PostgresRegistry& r) { r.put_user(row); });
}

bool JournaledRegistry::remove_user(const std::string& name) {
  std::lock_guard lock(mutex_);
  bool removed = true;
  write({{"write", "user_removed"}, {"name", name}}, [&](PostgresRegistry& r) { removed = r.remove_user(name); });
  return removed;
}

std::vector<UserRow> JournaledRegistry::users() {
  return answer("the lab's accounts", [&](PostgresRegistry& r) { return r.users(); });
}

void JournaledRegistry::record_calibration(const CampaignRow& row) {
  std::lock_guard lock(mutex_);
  write({{"write", "calibration"}, {"campaign_id", row.id}, {"row", campaign_row_json(row)}},
        [&](PostgresRegistry& r) { r.record_calibration(row); });
}

std::vector<CampaignRow> JournaledRegistry::unit_campaigns(const std::optional<std::string>& serial) {
  return answer("the units' calibrations", [&](PostgresRegistry& r) { return r.unit_campaigns(serial); });
}

std::optional<std::string> JournaledRegistry::limits_document() {
  return answer("the acceptance limits", [&](PostgresRegistry& r) { return r.limits_document(); });
}

void JournaledRegistry::put_limits_document(const std::string& document_json, const std::string& actor) {
  std::lock_guard lock(mutex_);
  write({{"write", "limits"}, {"document_json", document_json}, {"actor", actor}},
        [&](PostgresRegistry& r) { r.put_limits_document(document_json, actor); });
}

}  // namespace imucal::daemon
