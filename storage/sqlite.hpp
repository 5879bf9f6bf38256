// The one SQLite layer of imucal (run files and the daemon's database alike): a connection, the
// statements prepared on it and transactions, every SQLite result checked, every failure a
// SqliteError naming the file and saying what SQLite's code means for a person ("the disk is
// full ...; everything committed before is intact"). Only this layer calls sqlite3_*; the rest of
// the code sees none of SQLite's types.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>

struct sqlite3;
struct sqlite3_stmt;

namespace imucal::storage {

// Any failure of the storage layer, with a message for the operator.
class StorageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

namespace sql {

// A failure SQLite reported, with its primary result code.
class SqliteError : public StorageError {
 public:
  enum class Kind { full, damaged, busy, io, read_only, other };
  SqliteError(const std::string& what, int code);
  int code() const noexcept { return code_; }
  Kind kind() const noexcept;

 private:
  int code_;
};

class Connection;
void rollback_quietly(Connection& connection) noexcept;

class Connection {
 public:
  enum class Open { read_write, create };
  // `label` names the database in messages ("run database", "daemon database"). Waits up to 5 s
  // for a lock another connection holds rather than failing at once.
  Connection(const std::string& path, Open mode, std::string label);
  ~Connection();
  Connection(Connection&&) noexcept;
  Connection& operator=(Connection&&) noexcept;
  Connection(const Connection&) = delete;
  Connection& operator=(const Connection&) = delete;

  void exec(const std::string& sql);           // one or more statements, no rows
  std::int64_t query_int(const std::string& sql);  // the first column of the first row (a PRAGMA)
  std::int64_t last_insert_rowid() const noexcept;
  bool read_only() const noexcept;
  // Inside a transaction (BEGIN without its COMMIT or ROLLBACK yet).
  bool in_transaction() const noexcept;
  // A passive WAL checkpoint; another connection checkpointing at the same time is no failure.
  void checkpoint();

  const std::string& path() const noexcept { return path_; }
  // Throws StorageError "<label> '<path>': <reason>".
  [[noreturn]] void fail(const std::string& reason) const;
  [[noreturn]] void fail_sqlite(const std::string& what, int rc) const;

 private:
  friend class Statement;
  friend void rollback_quietly(Connection& connection) noexcept;
  sqlite3* db_ = nullptr;
  std::string path_;
  std::string label_;
};

// A prepared statement. Text bindings are copied; blobs are not (the caller steps while they live).
class Statement {
 public:
  Statement() = default;
  // `persistent`: prepared once and reused many times (the recorder's inserts).
  Statement(Connection& connection, const char* sql, bool persistent = false);
  Statement(Statement&&) noexcept = default;
  Statement& operator=(Statement&&) noexcept = default;

  Statement& bind(int index, std::int64_t value);
  Statement& bind(int index, double value);
  Statement& bind(int index, const std::string& text);
  Statement& bind(int index, const std::optional<double>& value);
  Statement& bind(int index, const std::optional<std::int64_t>& value);
  Statement& bind(int index, const std::optional<std::string>& value);
  Statement& bind_blob(int index, const void* data, std::size_t size);  // must outlive the step
  Statement& bind_null(int index);

  bool step();        // true while a row is available
  void run();         // a statement without rows, then reset
  void reset() noexcept;  // and clears the bindings

  std::int64_t column_int64(int col) const;
  double column_double(int col) const;
  bool column_is_null(int col) const;
  std::optional<double> column_optional_double(int col) const;
  std::optional<std::int64_t> column_optional_int64(int col) const;
  std::string column_text(int col) const;
  std::optional<std::string> column_optional_text(int col) const;
  std::span<const unsigned char> column_blob(int col) const;

  // Resets the statement when a use ends, also by an exception, so that it never holds a read
  // transaction open or keeps stale bindings.
  class Reset {
   public:
    explicit Reset(Statement& stmt) : stmt_(stmt) {}
    ~Reset() { stmt_.reset(); }
    Reset(const Reset&) = delete;
    Reset& operator=(const Reset&) = delete;

   private:
    Statement& stmt_;
  };

 private:
  struct Finalizer {
    void operator()(sqlite3_stmt* stmt) const noexcept;
  };
  void check(int rc, const char* what) const;
  const Connection* connection_ = nullptr;
  std::unique_ptr<sqlite3_stmt, Finalizer> stmt_;
};

// BEGIN IMMEDIATE .. commit(); rolled back when left without commit(), also by an exception.
// BEGIN's and COMMIT's results are checked (a BEGIN that fails throws: nothing runs outside the
// transaction it was meant for). Lock::read: a plain BEGIN, which takes no write lock: its reads
// see one snapshot of the database, whatever other connections commit meanwhile.
class Transaction {
 public:
  enum class Lock { write, read };
  explicit Transaction(Connection& connection, Lock lock = Lock::write);
  ~Transaction();
  void commit();
  Transaction(const Transaction&) = delete;
  Transaction& operator=(const Transaction&) = delete;

 private:
  Connection& connection_;
  bool done_ = false;
};

// ROLLBACK, never throwing: for a transaction begun by hand whose failure is being reported.
void rollback_quietly(Connection& connection) noexcept;

// Deletes a database file and the -wal, -shm and -journal files SQLite keeps beside it; files
// already absent are fine.
void remove_database_files(const std::string& path) noexcept;

}  // namespace sql

// A full disk on demand, for tests and fault drills, without root or mounts: every connection of
// this layer (run files and the daemon's database alike) opens through a thin SQLite VFS,
// "imucal-disk", over the platform's default one. While the disk is "full", every write to a
// database, journal or WAL file fails as a full file system fails it (SQLITE_FULL, what ENOSPC
// gives); reads go on. Off (the default) the VFS only forwards: one relaxed atomic load per write.
// Process-wide, as a real disk is shared by every database on it.
namespace disk_fault {
// On: every write fails from now on; off: writes go through again (space came back).
void set_full(bool full) noexcept;
// The disk fills once `bytes` more bytes have been written (the write that crosses fails, and
// every one after it until set_full(false)).
void fill_after_bytes(std::int64_t bytes) noexcept;
bool full() noexcept;
// Writes refused as on a full disk since the process started (a drill can tell that the full disk
// was met, not only switched on).
std::int64_t refused_writes() noexcept;
}  // namespace disk_fault

// The wall-clock stamps the storage writes (sessions, writer leases): Unix time in ms.
std::int64_t unix_ms_now();
}  // namespace imucal::storage
