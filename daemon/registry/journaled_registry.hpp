// The lab's PostgreSQL registry with the server away (issue 38, "the database away"): a stand
// that loses the server keeps running its campaign (the recording is local) and keeps the
// registry's writes in a journal on its own disk, in order, each fsynced before the call returns;
// when the server answers again they are replayed oldest first, each with its key (this stand,
// the journal's id, the write's number) committed in the same transaction
// (PostgresRegistry::apply_once), so nothing is lost and nothing applied twice, even by a replay
// that a crash interrupted and a restart repeats.
//
// Writes go to the server while it answers and the journal is empty; a write that meets the
// server unreachable (PgError::connection_lost) goes to the journal, and every later one behind
// it until the journal is replayed. A refusal of the server (a constraint) is the caller's, as
// without the journal; one met at replay is kept beside the journal (<journal>-refused.jsonl) and
// logged, and the replay goes on. Reads, and certificate numbers, need the server: while it is
// away they throw a PgError (connection lost, so is_database_failure: HTTP 503) saying so, with
// the writes waiting.
//
// The journal: one JSON object a line; the first a header (the journal's id, the next number),
// then the writes waiting. It is trimmed by rewriting it (temporary file, fsync, rename).
// One JournaledRegistry per journal (the daemon's data directory is its own, imucald.lock).
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include <nlohmann/json_fwd.hpp>

#include "daemon/registry/registry.hpp"

namespace imucal::daemon {

class PostgresRegistry;
class RegistryJournal;

class JournaledRegistry final : public Registry {
 public:
  // Connects to the server (throws PgError, connection lost, while it is away).
  using Connect = std::function<std::unique_ptr<PostgresRegistry>()>;
  struct Options {
    // While the server is away, a call tries it again no more often than this (a server out of
    // reach can keep a connection attempt waiting; the calls meanwhile answer at once).
    std::chrono::milliseconds call_retry_interval{std::chrono::seconds(2)};
    // A thread of its own calls retry() this often (zero: none, the owner calls retry()): a
    // stand idle between runs makes no calls, and its journal would wait for the next one.
    std::chrono::milliseconds retry_every{0};
    // The tests' seam for a reply lost on its way back: called after a write the server committed,
    // before it is taken as answered; a PgError (connection lost) from it is such a loss.
    std::function<void()> after_direct_write;
  };

  // Opens (or starts) the journal at `journal_path` and connects; a server away now is no error:
  // the journal takes the writes, a journal left from before is replayed once the server answers.
  JournaledRegistry(Connect connect, std::string journal_path, Options options);
  ~JournaledRegistry() override;

  std::string backend() const override { return "postgresql"; }
  // Throws while the server is away: a number cannot be taken without it (a run's certificate is
  // then issued at its first request, api.cpp campaign_certificate).
  std::int64_t next_certificate_sequence() override;
  std::int64_t max_certificate_sequence() override;
  // The server's (PostgresRegistry::take_certificate_number); throws while it is away, as above.
  CertificateNumber take_certificate_number() override;
  std::optional<CertificateRow> certificate(std::int64_t campaign_id) override;
  void insert_certificate(const CertificateRow& row) override;
  void insert_issued(const IssuedCertificateRow& row) override;
  std::optional<IssuedCertificateRow> issued(const std::string& number) override;
  std::optional<IssuedCertificateRow> current_issued(std::int64_t campaign_id) override;
  std::vector<IssuedCertificateRow> issued_history(std::int64_t campaign_id) override;
  std::vector<std::int64_t> campaigns_with_issued() override;
  // Journaled: true (whether a page was stored before is known at replay, where the first is kept).
  bool insert_issued_page(const IssuedPageRow& row) override;
  std::optional<IssuedPageRow> issued_page(const std::string& number, bool with_html) override;
  void insert_overdue_override(const OverdueOverrideRow& row) override;
  void remove_overdue_override(std::int64_t campaign_id) override;
  std::optional<OverdueOverrideRow> overdue_override(std::int64_t campaign_id) override;
  // Journaled: the entry with its time (t_ms, else now: the time it keeps at replay), seq 0 and
  // empty hashes, as the chain's head is on the server: it is chained at replay, in order.
  AuditEntry append_audit(const std::string& actor, const std::string& action, const std::string& subject,
                          const std::string& details_json, std::optional<std::int64_t> t_ms) override;
  std::vector<AuditEntry> audit_entries(const AuditQuery& query) override;
  AuditChain audit_chain() override;
  // Journaled as the row was when recorded: its replay replaces what the server has of it, in
  // the order the records were made.
  void record_calibration(const CampaignRow& row) override;
  std::vector<CampaignRow> unit_campaigns(const std::optional<std::string>& serial) override;
  std::optional<std::string> limits_document() override;
  void put_limits_document(const std::string& document_json, const std::string& actor) override;

  // Stands. A registration is journaled as any write (it arrives when the server returns); a
  // heartbeat's state is not: it is volatile, only the latest matters, and the first heartbeat
  // after the server returns brings it (a journal of states would replay minutes of stale ones).
  // stands() needs the server, as the other reads.
  void register_stand(const StandRow& row) override;
  bool report_stand_state(const std::string& name, const std::string& state_json, std::int64_t t_ms) override;
  std::vector<StandRow> stands() override;
  // Journaled as any write; remove_user then says true (whether there was one is known at replay).
  void put_user(const UserRow& row) override;
  bool remove_user(const std::string& name) override;
  std::vector<UserRow> users() override;

  bool reachable() const override { return reachable_; }
  std::int64_t pending_writes() const override { return pending_; }

  // Replays the journal now if the server answers: true when nothing waits and the server
  // answered (also when there was nothing to replay).
  bool retry();
  const std::string& journal_path() const { return journal_path_; }

 private:
  using Call = std::function<void(PostgresRegistry&)>;
  // Under mutex_.
  void write(const nlohmann::json& entry, const Call& apply);
  void read(const char* what, const Call& query);
  // A read of its own: takes mutex_, asks `query` of the server by read() and returns its answer.
  template <class Query>
  auto answer(const char* what, const Query& query);
  bool ready(bool force);
  PostgresRegistry* connected();
  bool replay();
  bool replay_one(const nlohmann::json& entry);
  void went_away(const std::string& why);
  void answered();
  // `call` on the server: true when it answered; false when the connection was lost (noted by
  // went_away); any other failure propagates.
  bool asked(const Call& call);
  void retry_loop();

  Connect connect_;
  std::string journal_path_;
  Options options_;
  std::mutex mutex_;
  std::unique_ptr<PostgresRegistry> server_;  // null until connected once
  std::unique_ptr<RegistryJournal> journal_;
  std::string last_failure_;  // the server's (or libpq's) words when it went away
  std::chrono::steady_clock::time_point last_attempt_{};
  std::atomic<bool> reachable_{false};
  std::atomic<std::int64_t> pending_{0};
  // The keys of the writes tried at once: this process's own journal name (the journal's id and a
  // random part: a restart never reuses a key), numbered from 1.
  std::string direct_journal_;
  std::int64_t direct_writes_ = 0;
  // retry_every's thread.
  std::mutex stop_mutex_;
  std::condition_variable stop_cv_;
  bool stopping_ = false;
  std::thread retry_thread_;
};

}  // namespace imucal::daemon
