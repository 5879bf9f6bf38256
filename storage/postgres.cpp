#include "storage/postgres.hpp"

#include <libpq-fe.h>

#include <charconv>
#include <cstdio>
#include <utility>

namespace imucal::storage::pg {

namespace {

// The statement as a message names it: its text on one line, shortened.
std::string statement_name(const std::string& sql) {
  std::string out;
  bool space = false;
  for (const char c : sql) {
    if (c == '\n' || c == '\t' || c == ' ') {
      space = !out.empty();
      continue;
    }
    if (space) out += ' ';
    space = false;
    out += c;
  }
  constexpr std::size_t kMax = 120;
  if (out.size() > kMax) out = out.substr(0, kMax) + "...";
  return out;
}

// libpq's message without its trailing newline.
std::string trimmed(const char* message) {
  std::string out = message != nullptr ? message : "";
  while (!out.empty() && (out.back() == '\n' || out.back() == ' ')) out.pop_back();
  return out;
}

// The server's notices (CREATE ... IF NOT EXISTS "skipping") are not printed on stderr.
void ignore_notice(void* /*arg*/, const char* /*message*/) {}

}  // namespace

PgError::PgError(const std::string& what, std::string sqlstate, bool connection_lost)
    : StorageError(what), sqlstate_(std::move(sqlstate)), connection_lost_(connection_lost) {}

// ---------------------------------------------------------------------------------------------
// Param

Param::Param(std::int64_t value) : text_(std::to_string(value)) {}
Param::Param(int value) : text_(std::to_string(value)) {}
Param::Param(double value) {
  char buffer[32];
  const auto [end, ec] = std::to_chars(buffer, buffer + sizeof buffer, value);  // shortest exact text
  text_ = ec == std::errc() ? std::string(buffer, end) : std::to_string(value);
}
Param::Param(bool value) : text_(value ? "true" : "false") {}
Param::Param(std::string value) : text_(std::move(value)) {}
Param::Param(const char* value) : text_(std::string(value)) {}
Param::Param(const std::optional<std::string>& value) : text_(value) {}
Param::Param(const std::optional<std::int64_t>& value) {
  if (value) text_ = std::to_string(*value);
}
Param::Param(const std::optional<double>& value) {
  if (value) *this = Param(*value);
}

// ---------------------------------------------------------------------------------------------
// Result

void Result::Clear::operator()(pg_result* result) const noexcept { PQclear(result); }

Result::Result(std::shared_ptr<pg_result> result, std::string statement)
    : result_(std::move(result)), statement_(std::move(statement)) {}

int Result::rows() const noexcept { return result_ ? PQntuples(result_.get()) : 0; }
int Result::columns() const noexcept { return result_ ? PQnfields(result_.get()) : 0; }

const char* Result::cell(int row, int col) const {
  if (row < 0 || row >= rows() || col < 0 || col >= columns())
    throw PgError("'" + statement_ + "': no row " + std::to_string(row) + ", column " + std::to_string(col), "",
                  false);
  return PQgetvalue(result_.get(), row, col);
}

bool Result::is_null(int row, int col) const {
  cell(row, col);
  return PQgetisnull(result_.get(), row, col) != 0;
}

std::string Result::text(int row, int col) const { return cell(row, col); }

std::int64_t Result::int64(int row, int col) const {
  const std::string t = text(row, col);
  std::int64_t value = 0;
  const auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), value);
  if (ec != std::errc() || end != t.data() + t.size())
    throw PgError("'" + statement_ + "': column " + std::to_string(col) + " is no integer ('" + t + "')", "", false);
  return value;
}

double Result::number(int row, int col) const {
  const std::string t = text(row, col);
  double value = 0.0;
  const auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), value);
  if (ec != std::errc() || end != t.data() + t.size())
    throw PgError("'" + statement_ + "': column " + std::to_string(col) + " is no number ('" + t + "')", "", false);
  return value;
}

bool Result::boolean(int row, int col) const { return text(row, col) == "t"; }

std::optional<std::string> Result::optional_text(int row, int col) const {
  if (is_null(row, col)) return std::nullopt;
  return text(row, col);
}

std::optional<std::int64_t> Result::optional_int64(int row, int col) const {
  if (is_null(row, col)) return std::nullopt;
  return int64(row, col);
}

std::int64_t Result::affected() const {
  const std::string t = result_ ? PQcmdTuples(result_.get()) : "";
  std::int64_t value = 0;
  std::from_chars(t.data(), t.data() + t.size(), value);
  return value;
}

// ---------------------------------------------------------------------------------------------
// Connection

Connection::Connection(const std::string& conninfo, std::string label) : label_(std::move(label)) {
  // Bounds a server that does not answer at all (a host switched off, a network black hole): libpq
  // waits on the TCP stack's minutes otherwise, at connect and on a half-open connection. The
  // connection string's own values win (libpq takes the last of a repeated keyword, and the string
  // is expanded where `dbname` stands, after these).
  static const char* const keywords[] = {"connect_timeout", "keepalives_idle", "keepalives_interval", "keepalives_count",
                                         "tcp_user_timeout", "dbname", nullptr};
  const char* const values[] = {"10", "10", "5", "3", "30000", conninfo.c_str(), nullptr};
  conn_ = PQconnectdbParams(keywords, values, /*expand_dbname=*/1);
  if (conn_ == nullptr) throw PgError(label_ + ": cannot connect (out of memory)", "", true);
  if (PQstatus(conn_) != CONNECTION_OK) {
    const std::string message = trimmed(PQerrorMessage(conn_));
    PQfinish(conn_);
    conn_ = nullptr;
    throw PgError(label_ + ": cannot connect to the PostgreSQL server: " + message, "", true);
  }
  PQsetNoticeProcessor(conn_, ignore_notice, nullptr);
}

Connection::~Connection() {
  if (conn_ != nullptr) PQfinish(conn_);
}

Connection::Connection(Connection&& other) noexcept
    : conn_(std::exchange(other.conn_, nullptr)), label_(std::move(other.label_)), broken_(other.broken_) {}

Connection& Connection::operator=(Connection&& other) noexcept {
  if (this != &other) {
    if (conn_ != nullptr) PQfinish(conn_);
    conn_ = std::exchange(other.conn_, nullptr);
    label_ = std::move(other.label_);
    broken_ = other.broken_;
  }
  return *this;
}

void Connection::fail(const std::string& statement, pg_result* result) {
  const char* state = result != nullptr ? PQresultErrorField(result, PG_DIAG_SQLSTATE) : nullptr;
  std::string message = trimmed(result != nullptr ? PQresultErrorMessage(result) : nullptr);
  if (message.empty()) message = trimmed(PQerrorMessage(conn_));
  // Lost: libpq says so, or the error is libpq's own (no SQLSTATE: the server closed the
  // connection), a connection exception (class 08) or the server shutting down (57P01..57P03).
  const std::string code = state != nullptr ? state : "";
  const bool lost = PQstatus(conn_) != CONNECTION_OK || code.empty() || code.rfind("08", 0) == 0 ||
                    code == "57P01" || code == "57P02" || code == "57P03";
  if (lost) broken_ = true;
  std::string what = label_ + ": '" + statement_name(statement) + "' failed: " + message;
  if (lost) what += " (the connection to the server was lost; nothing of the open transaction was committed)";
  throw PgError(what, code, lost);
}

Result Connection::exec(const std::string& sql, const std::vector<Param>& params) {
  if (conn_ == nullptr) throw PgError(label_ + ": '" + statement_name(sql) + "': the connection is closed", "", true);
  std::vector<const char*> values;
  values.reserve(params.size());
  for (const Param& p : params) {
    const std::optional<std::string>& text = p.text();
    values.push_back(text.has_value() ? text->c_str() : nullptr);  // none: SQL NULL
  }
  std::shared_ptr<pg_result> result(
      PQexecParams(conn_, sql.c_str(), static_cast<int>(values.size()), nullptr, values.data(), nullptr, nullptr, 0),
      Result::Clear{});
  const ExecStatusType status = result ? PQresultStatus(result.get()) : PGRES_FATAL_ERROR;
  if (status != PGRES_COMMAND_OK && status != PGRES_TUPLES_OK) fail(sql, result.get());
  return Result(std::move(result), statement_name(sql));
}

void Connection::exec_script(const std::string& sql) {
  if (conn_ == nullptr) throw PgError(label_ + ": '" + statement_name(sql) + "': the connection is closed", "", true);
  std::unique_ptr<pg_result, Result::Clear> result(PQexec(conn_, sql.c_str()));
  const ExecStatusType status = result ? PQresultStatus(result.get()) : PGRES_FATAL_ERROR;
  if (status != PGRES_COMMAND_OK && status != PGRES_TUPLES_OK) fail(sql, result.get());
}

bool Connection::in_transaction() const noexcept {
  return conn_ != nullptr && PQtransactionStatus(conn_) != PQTRANS_IDLE;
}

bool Connection::ok() const noexcept { return conn_ != nullptr && !broken_ && PQstatus(conn_) == CONNECTION_OK; }

// ---------------------------------------------------------------------------------------------
// Transaction

Transaction::Transaction(Connection& connection, bool serializable) : connection_(connection) {
  connection_.exec(serializable ? "BEGIN ISOLATION LEVEL SERIALIZABLE" : "BEGIN");
}

void Transaction::commit() {
  connection_.exec("COMMIT");
  done_ = true;
}

Transaction::~Transaction() {
  if (done_ || connection_.conn_ == nullptr) return;
  // The failure being reported is the one worth reporting: ROLLBACK's own result is not checked
  // (on a lost connection there is nothing to roll back).
  PQclear(PQexec(connection_.conn_, "ROLLBACK"));
}

}  // namespace imucal::storage::pg
