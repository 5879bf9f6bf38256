// The one PostgreSQL layer of imucal (the registry on a lab's server, issue 38), beside the SQLite
// one (sqlite.hpp) and with its habits: a connection that closes itself, statements with their
// values passed as parameters only (never spliced into the SQL), transactions rolled back when left
// without commit, every failure a PgError naming the database, the statement and the server's
// message. Only this layer calls libpq; the rest of the code sees none of its types.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "storage/sqlite.hpp"  // StorageError

struct pg_conn;
struct pg_result;

namespace imucal::storage::pg {

// A failure of the server or of the connection to it.
class PgError : public StorageError {
 public:
  // `sqlstate`: the server's SQLSTATE ("23505" a unique violation), empty when there is none (the
  // connection failed or was lost).
  PgError(const std::string& what, std::string sqlstate, bool connection_lost);
  const std::string& sqlstate() const noexcept { return sqlstate_; }
  // The server could not be reached or the connection broke: the statement may be repeated once
  // the server is back; nothing of an open transaction was committed.
  bool connection_lost() const noexcept { return connection_lost_; }
  bool unique_violation() const noexcept { return sqlstate_ == "23505"; }

 private:
  std::string sqlstate_;
  bool connection_lost_;
};

// One value of a statement's parameters, sent as text ($1, $2, ...); none is SQL NULL.
class Param {
 public:
  Param(std::nullopt_t) {}  // NOLINT(google-explicit-constructor): a parameter list reads as values
  Param(std::int64_t value);         // NOLINT(google-explicit-constructor)
  Param(int value);                  // NOLINT(google-explicit-constructor)
  Param(double value);               // NOLINT(google-explicit-constructor)
  Param(bool value);                 // NOLINT(google-explicit-constructor)
  Param(std::string value);          // NOLINT(google-explicit-constructor)
  Param(const char* value);          // NOLINT(google-explicit-constructor)
  Param(const std::optional<std::string>& value);   // NOLINT(google-explicit-constructor)
  Param(const std::optional<std::int64_t>& value);  // NOLINT(google-explicit-constructor)
  Param(const std::optional<double>& value);        // NOLINT(google-explicit-constructor)
  const std::optional<std::string>& text() const noexcept { return text_; }

 private:
  std::optional<std::string> text_;
};

// The rows a statement returned, read as text and converted; a column read as a number that is
// not one throws PgError naming the statement.
class Result {
 public:
  Result() = default;
  int rows() const noexcept;
  int columns() const noexcept;
  bool is_null(int row, int col) const;
  std::string text(int row, int col) const;
  std::int64_t int64(int row, int col) const;
  double number(int row, int col) const;
  bool boolean(int row, int col) const;
  std::optional<std::string> optional_text(int row, int col) const;
  std::optional<std::int64_t> optional_int64(int row, int col) const;
  // The number of rows an INSERT, UPDATE or DELETE changed.
  std::int64_t affected() const;

 private:
  friend class Connection;
  struct Clear {
    void operator()(pg_result* result) const noexcept;
  };
  Result(std::shared_ptr<pg_result> result, std::string statement);
  const char* cell(int row, int col) const;
  std::shared_ptr<pg_result> result_;
  std::string statement_;
};

class Connection {
 public:
  // `conninfo`: a libpq connection string ("host=/run/pg dbname=registry", "postgresql://...").
  // `label` names the database in messages ("registry"). Throws PgError when the server cannot
  // be reached or refuses the connection.
  Connection(const std::string& conninfo, std::string label);
  ~Connection();
  Connection(Connection&&) noexcept;
  Connection& operator=(Connection&&) noexcept;
  Connection(const Connection&) = delete;
  Connection& operator=(const Connection&) = delete;

  // One statement with its parameters ($1 ...), its rows.
  Result exec(const std::string& sql, const std::vector<Param>& params = {});
  // Several statements without parameters or rows (a schema).
  void exec_script(const std::string& sql);
  bool in_transaction() const noexcept;
  // Whether the connection is still up (false once a statement found the server gone: a new
  // Connection is then needed).
  bool ok() const noexcept;
  const std::string& label() const noexcept { return label_; }

 private:
  friend class Transaction;
  [[noreturn]] void fail(const std::string& statement, pg_result* result);
  pg_conn* conn_ = nullptr;
  std::string label_;
  bool broken_ = false;  // a failure said the connection was lost
};

// BEGIN .. commit(); rolled back when left without commit(), also by an exception. `serializable`:
// ISOLATION LEVEL SERIALIZABLE instead of READ COMMITTED.
class Transaction {
 public:
  explicit Transaction(Connection& connection, bool serializable = false);
  ~Transaction();
  void commit();
  Transaction(const Transaction&) = delete;
  Transaction& operator=(const Transaction&) = delete;

 private:
  Connection& connection_;
  bool done_ = false;
};

}  // namespace imucal::storage::pg
