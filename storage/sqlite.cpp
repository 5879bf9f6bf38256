#include "storage/sqlite.hpp"

#include <sqlite3.h>

#include <chrono>
#include <filesystem>

namespace imucal::storage::sql {

namespace {

// SQLite's message, with what it means for the data where a person can act on it.
std::string reason(sqlite3* db, int rc) {
  const std::string message = db != nullptr ? sqlite3_errmsg(db) : sqlite3_errstr(rc);
  switch (rc & 0xff) {
    case SQLITE_FULL:
      return "the disk is full or the file reached its size limit (" + message +
             "); the uncommitted writes were rolled back, everything committed before is intact";
    case SQLITE_CORRUPT:
    case SQLITE_NOTADB:
      return "the file is damaged (" + message + ")";
    case SQLITE_BUSY:
    case SQLITE_LOCKED:
      return "the file is locked by another connection (" + message + ")";
    case SQLITE_IOERR:
      return "I/O error (" + message + ")";
    case SQLITE_READONLY:
      return "the file cannot be written (" + message + ")";
    default:
      return message;
  }
}

}  // namespace

SqliteError::SqliteError(const std::string& what, int code) : StorageError(what), code_(code) {}

SqliteError::Kind SqliteError::kind() const noexcept {
  switch (code_ & 0xff) {
    case SQLITE_FULL: return Kind::full;
    case SQLITE_CORRUPT:
    case SQLITE_NOTADB: return Kind::damaged;
    case SQLITE_BUSY:
    case SQLITE_LOCKED: return Kind::busy;
    case SQLITE_IOERR: return Kind::io;
    case SQLITE_READONLY: return Kind::read_only;
    default: return Kind::other;
  }
}

// ---------------------------------------------------------------------------------------------
// Connection

Connection::Connection(const std::string& path, Open mode, std::string label) : path_(path), label_(std::move(label)) {
  const int flags = mode == Open::create ? SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE : SQLITE_OPEN_READWRITE;
  const int rc = sqlite3_open_v2(path.c_str(), &db_, flags, nullptr);
  if (rc != SQLITE_OK) {
    // sqlite3_open_v2 may hand out a handle even when it fails.
    const std::string message = db_ != nullptr ? sqlite3_errmsg(db_) : sqlite3_errstr(rc);
    sqlite3_close_v2(db_);
    db_ = nullptr;
    throw SqliteError(label_ + " '" + path_ + "': cannot open: " + message, rc);
  }
  sqlite3_extended_result_codes(db_, 1);
  // A reader (the web UI, `imucal calibrate`) may hold the file briefly; wait instead of failing.
  sqlite3_busy_timeout(db_, 5000);
}

Connection::~Connection() {
  if (db_ != nullptr) sqlite3_close_v2(db_);
}

Connection::Connection(Connection&& other) noexcept
    : db_(other.db_), path_(std::move(other.path_)), label_(std::move(other.label_)) {
  other.db_ = nullptr;
}

Connection& Connection::operator=(Connection&& other) noexcept {
  if (this != &other) {
    if (db_ != nullptr) sqlite3_close_v2(db_);
    db_ = other.db_;
    path_ = std::move(other.path_);
    label_ = std::move(other.label_);
    other.db_ = nullptr;
  }
  return *this;
}

void Connection::fail(const std::string& why) const { throw StorageError(label_ + " '" + path_ + "': " + why); }

void Connection::fail_sqlite(const std::string& what, int rc) const {
  throw SqliteError(label_ + " '" + path_ + "': " + what + ": " + reason(db_, rc), rc);
}

void Connection::exec(const std::string& sql) {
  const int rc = sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, nullptr);
  if (rc != SQLITE_OK) fail_sqlite("'" + sql + "' failed", rc);
}

std::int64_t Connection::query_int(const std::string& sql) {
  Statement stmt(*this, sql.c_str());
  Statement::Reset reset(stmt);
  if (!stmt.step()) fail("'" + sql + "' returned nothing");
  return stmt.column_int64(0);
}

std::int64_t Connection::last_insert_rowid() const noexcept { return sqlite3_last_insert_rowid(db_); }

bool Connection::read_only() const noexcept { return sqlite3_db_readonly(db_, "main") == 1; }

void Connection::checkpoint() {
  const int rc = sqlite3_wal_checkpoint_v2(db_, nullptr, SQLITE_CHECKPOINT_PASSIVE, nullptr, nullptr);
  // BUSY: another connection is checkpointing right now, which does the same job.
  if (rc != SQLITE_OK && (rc & 0xff) != SQLITE_BUSY) fail_sqlite("checkpoint failed", rc);
}

// ---------------------------------------------------------------------------------------------
// Statement

void Statement::Finalizer::operator()(sqlite3_stmt* stmt) const noexcept { sqlite3_finalize(stmt); }

Statement::Statement(Connection& connection, const char* sql, bool persistent) : connection_(&connection) {
  sqlite3_stmt* raw = nullptr;
  const int rc = sqlite3_prepare_v3(connection.db_, sql, -1, persistent ? SQLITE_PREPARE_PERSISTENT : 0, &raw, nullptr);
  if (rc != SQLITE_OK) connection.fail_sqlite(std::string("cannot prepare '") + sql + "'", rc);
  stmt_.reset(raw);
}

void Statement::check(int rc, const char* what) const {
  if (rc != SQLITE_OK) connection_->fail_sqlite(std::string(what) + " '" + sqlite3_sql(stmt_.get()) + "'", rc);
}

Statement& Statement::bind(int index, std::int64_t value) {
  check(sqlite3_bind_int64(stmt_.get(), index, static_cast<sqlite3_int64>(value)), "bind");
  return *this;
}
Statement& Statement::bind(int index, double value) {
  check(sqlite3_bind_double(stmt_.get(), index, value), "bind");
  return *this;
}
Statement& Statement::bind(int index, const std::string& text) {
  // Copied: a temporary string may be bound.
  check(sqlite3_bind_text64(stmt_.get(), index, text.data(), text.size(), SQLITE_TRANSIENT, SQLITE_UTF8), "bind");
  return *this;
}
Statement& Statement::bind(int index, const std::optional<double>& value) {
  return value ? bind(index, *value) : bind_null(index);
}
Statement& Statement::bind(int index, const std::optional<std::int64_t>& value) {
  return value ? bind(index, *value) : bind_null(index);
}
Statement& Statement::bind(int index, const std::optional<std::string>& value) {
  return value ? bind(index, *value) : bind_null(index);
}
Statement& Statement::bind_blob(int index, const void* data, std::size_t size) {
  // Not copied: frame chunks are large and every caller steps while they live.
  check(sqlite3_bind_blob64(stmt_.get(), index, data, size, SQLITE_STATIC), "bind");
  return *this;
}
Statement& Statement::bind_null(int index) {
  check(sqlite3_bind_null(stmt_.get(), index), "bind");
  return *this;
}

bool Statement::step() {
  const int rc = sqlite3_step(stmt_.get());
  if (rc == SQLITE_ROW) return true;
  if (rc == SQLITE_DONE) return false;
  connection_->fail_sqlite(std::string("'") + sqlite3_sql(stmt_.get()) + "' failed", rc);
}

void Statement::run() {
  Reset reset(*this);
  while (step()) {
  }
}

void Statement::reset() noexcept {
  sqlite3_reset(stmt_.get());
  sqlite3_clear_bindings(stmt_.get());
}

std::int64_t Statement::column_int64(int col) const { return sqlite3_column_int64(stmt_.get(), col); }
double Statement::column_double(int col) const { return sqlite3_column_double(stmt_.get(), col); }
bool Statement::column_is_null(int col) const { return sqlite3_column_type(stmt_.get(), col) == SQLITE_NULL; }
std::optional<double> Statement::column_optional_double(int col) const {
  if (column_is_null(col)) return std::nullopt;
  return column_double(col);
}
std::optional<std::int64_t> Statement::column_optional_int64(int col) const {
  if (column_is_null(col)) return std::nullopt;
  return column_int64(col);
}
std::string Statement::column_text(int col) const {
  const auto* text = sqlite3_column_text(stmt_.get(), col);
  const int size = sqlite3_column_bytes(stmt_.get(), col);
  if (text == nullptr) return {};
  return std::string(reinterpret_cast<const char*>(text), static_cast<std::size_t>(size));
}
std::optional<std::string> Statement::column_optional_text(int col) const {
  if (column_is_null(col)) return std::nullopt;
  return column_text(col);
}
std::span<const unsigned char> Statement::column_blob(int col) const {
  const void* data = sqlite3_column_blob(stmt_.get(), col);
  const int size = sqlite3_column_bytes(stmt_.get(), col);  // after column_blob, as documented
  if (data == nullptr) return {};
  return {static_cast<const unsigned char*>(data), static_cast<std::size_t>(size)};
}

// ---------------------------------------------------------------------------------------------
// Transaction

Transaction::Transaction(Connection& connection) : connection_(connection) { connection_.exec("BEGIN IMMEDIATE"); }

void Transaction::commit() {
  connection_.exec("COMMIT");
  done_ = true;
}

Transaction::~Transaction() {
  if (!done_) rollback_quietly(connection_);
}

void rollback_quietly(Connection& connection) noexcept {
  // SQLite may have rolled back by itself (SQLITE_FULL at COMMIT does); the original error is
  // the one worth reporting.
  sqlite3_exec(connection.db_, "ROLLBACK", nullptr, nullptr, nullptr);
}

void remove_database_files(const std::string& path) noexcept {
  std::error_code ignored;
  for (const char* suffix : {"", "-wal", "-shm", "-journal"}) std::filesystem::remove(path + suffix, ignored);
}

}  // namespace imucal::storage::sql

namespace imucal::storage {

std::int64_t unix_ms_now() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

}  // namespace imucal::storage
