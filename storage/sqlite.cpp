#include "storage/sqlite.hpp"

#include <sqlite3.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <limits>

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
// The "imucal-disk" VFS (disk_fault in sqlite.hpp): forwards everything to the default VFS, and
// fails writes while the disk is made full. A file of this VFS is the default VFS's file with a
// header in front, whose methods forward to it.

namespace {

constexpr const char* kVfsName = "imucal-disk";
// Bytes that may still be written: kUnlimited while the switch is off (the only value the
// forwarding path looks at), <= 0 while the disk is full, a budget in between.
constexpr std::int64_t kUnlimited = std::numeric_limits<std::int64_t>::max();
std::atomic<std::int64_t> g_room_bytes{kUnlimited};
std::atomic<std::int64_t> g_refused_writes{0};

struct DiskFile {
  sqlite3_file base;   // what SQLite sees; pMethods are ours
  sqlite3_file* real;  // the default VFS's file, in the same allocation just after this header
};

sqlite3_file* real_of(sqlite3_file* f) { return reinterpret_cast<DiskFile*>(f)->real; }
sqlite3_vfs* base_vfs(sqlite3_vfs* vfs) { return static_cast<sqlite3_vfs*>(vfs->pAppData); }

// Whether a write of `bytes` finds room; the cheap case (switch off) is one relaxed load.
bool room_for(int bytes) noexcept {
  std::int64_t room = g_room_bytes.load(std::memory_order_relaxed);
  if (room == kUnlimited) return true;
  for (;;) {
    if (room <= 0) return false;
    const std::int64_t left = room - bytes;
    // A write that does not fit fails and leaves the disk full, as the file system would.
    if (g_room_bytes.compare_exchange_weak(room, left < 0 ? 0 : left, std::memory_order_relaxed))
      return left >= 0;
    if (room == kUnlimited) return true;
  }
}

int disk_close(sqlite3_file* f) {
  sqlite3_file* real = real_of(f);
  const int rc = real->pMethods != nullptr ? real->pMethods->xClose(real) : SQLITE_OK;
  f->pMethods = nullptr;
  return rc;
}
int disk_read(sqlite3_file* f, void* out, int bytes, sqlite3_int64 offset) {
  return real_of(f)->pMethods->xRead(real_of(f), out, bytes, offset);
}
int disk_write(sqlite3_file* f, const void* data, int bytes, sqlite3_int64 offset) {
  if (!room_for(bytes)) {
    g_refused_writes.fetch_add(1, std::memory_order_relaxed);
    return SQLITE_FULL;
  }
  return real_of(f)->pMethods->xWrite(real_of(f), data, bytes, offset);
}
int disk_truncate(sqlite3_file* f, sqlite3_int64 size) { return real_of(f)->pMethods->xTruncate(real_of(f), size); }
int disk_sync(sqlite3_file* f, int flags) { return real_of(f)->pMethods->xSync(real_of(f), flags); }
int disk_file_size(sqlite3_file* f, sqlite3_int64* size) { return real_of(f)->pMethods->xFileSize(real_of(f), size); }
int disk_lock(sqlite3_file* f, int level) { return real_of(f)->pMethods->xLock(real_of(f), level); }
int disk_unlock(sqlite3_file* f, int level) { return real_of(f)->pMethods->xUnlock(real_of(f), level); }
int disk_check_reserved(sqlite3_file* f, int* out) {
  return real_of(f)->pMethods->xCheckReservedLock(real_of(f), out);
}
int disk_file_control(sqlite3_file* f, int op, void* arg) {
  return real_of(f)->pMethods->xFileControl(real_of(f), op, arg);
}
int disk_sector_size(sqlite3_file* f) { return real_of(f)->pMethods->xSectorSize(real_of(f)); }
int disk_device_characteristics(sqlite3_file* f) {
  return real_of(f)->pMethods->xDeviceCharacteristics(real_of(f));
}
int disk_shm_map(sqlite3_file* f, int page, int page_size, int extend, void volatile** out) {
  return real_of(f)->pMethods->xShmMap(real_of(f), page, page_size, extend, out);
}
int disk_shm_lock(sqlite3_file* f, int offset, int n, int flags) {
  return real_of(f)->pMethods->xShmLock(real_of(f), offset, n, flags);
}
void disk_shm_barrier(sqlite3_file* f) { real_of(f)->pMethods->xShmBarrier(real_of(f)); }
int disk_shm_unmap(sqlite3_file* f, int delete_flag) { return real_of(f)->pMethods->xShmUnmap(real_of(f), delete_flag); }
int disk_fetch(sqlite3_file* f, sqlite3_int64 offset, int bytes, void** out) {
  return real_of(f)->pMethods->xFetch(real_of(f), offset, bytes, out);
}
int disk_unfetch(sqlite3_file* f, sqlite3_int64 offset, void* page) {
  return real_of(f)->pMethods->xUnfetch(real_of(f), offset, page);
}

// One method table per version of the default VFS's files: SQLite calls the methods of a version
// only when iVersion says they exist, so ours must not claim more than the real file has.
sqlite3_io_methods disk_methods(int version) {
  sqlite3_io_methods m{};
  m.iVersion = version;
  m.xClose = disk_close;
  m.xRead = disk_read;
  m.xWrite = disk_write;
  m.xTruncate = disk_truncate;
  m.xSync = disk_sync;
  m.xFileSize = disk_file_size;
  m.xLock = disk_lock;
  m.xUnlock = disk_unlock;
  m.xCheckReservedLock = disk_check_reserved;
  m.xFileControl = disk_file_control;
  m.xSectorSize = disk_sector_size;
  m.xDeviceCharacteristics = disk_device_characteristics;
  if (version >= 2) {
    m.xShmMap = disk_shm_map;
    m.xShmLock = disk_shm_lock;
    m.xShmBarrier = disk_shm_barrier;
    m.xShmUnmap = disk_shm_unmap;
  }
  if (version >= 3) {
    m.xFetch = disk_fetch;
    m.xUnfetch = disk_unfetch;
  }
  return m;
}
const sqlite3_io_methods kDiskMethods[3] = {disk_methods(1), disk_methods(2), disk_methods(3)};

int disk_open(sqlite3_vfs* vfs, sqlite3_filename name, sqlite3_file* f, int flags, int* out_flags) {
  auto* file = reinterpret_cast<DiskFile*>(f);
  file->base.pMethods = nullptr;
  file->real = reinterpret_cast<sqlite3_file*>(file + 1);
  file->real->pMethods = nullptr;
  sqlite3_vfs* base = base_vfs(vfs);
  const int rc = base->xOpen(base, name, file->real, flags, out_flags);
  // SQLite closes a file whose pMethods are set even when the open failed: forward that too.
  if (file->real->pMethods != nullptr) {
    const int version = std::clamp(file->real->pMethods->iVersion, 1, 3);
    file->base.pMethods = &kDiskMethods[version - 1];
  }
  return rc;
}
int disk_delete(sqlite3_vfs* vfs, const char* name, int sync_dir) {
  return base_vfs(vfs)->xDelete(base_vfs(vfs), name, sync_dir);
}
int disk_access(sqlite3_vfs* vfs, const char* name, int flags, int* out) {
  return base_vfs(vfs)->xAccess(base_vfs(vfs), name, flags, out);
}
int disk_full_pathname(sqlite3_vfs* vfs, const char* name, int size, char* out) {
  return base_vfs(vfs)->xFullPathname(base_vfs(vfs), name, size, out);
}
void* disk_dl_open(sqlite3_vfs* vfs, const char* name) { return base_vfs(vfs)->xDlOpen(base_vfs(vfs), name); }
void disk_dl_error(sqlite3_vfs* vfs, int size, char* out) { base_vfs(vfs)->xDlError(base_vfs(vfs), size, out); }
void (*disk_dl_sym(sqlite3_vfs* vfs, void* handle, const char* symbol))(void) {
  return base_vfs(vfs)->xDlSym(base_vfs(vfs), handle, symbol);
}
void disk_dl_close(sqlite3_vfs* vfs, void* handle) { base_vfs(vfs)->xDlClose(base_vfs(vfs), handle); }
int disk_randomness(sqlite3_vfs* vfs, int size, char* out) {
  return base_vfs(vfs)->xRandomness(base_vfs(vfs), size, out);
}
int disk_sleep(sqlite3_vfs* vfs, int us) { return base_vfs(vfs)->xSleep(base_vfs(vfs), us); }
int disk_current_time(sqlite3_vfs* vfs, double* out) { return base_vfs(vfs)->xCurrentTime(base_vfs(vfs), out); }
int disk_get_last_error(sqlite3_vfs* vfs, int size, char* out) {
  return base_vfs(vfs)->xGetLastError != nullptr ? base_vfs(vfs)->xGetLastError(base_vfs(vfs), size, out) : 0;
}
int disk_current_time_int64(sqlite3_vfs* vfs, sqlite3_int64* out) {
  return base_vfs(vfs)->xCurrentTimeInt64(base_vfs(vfs), out);
}

// Registers the VFS once (not as the default: only this layer's connections name it) and returns
// its name.
const char* disk_vfs_name() {
  static const bool registered = [] {
    sqlite3_vfs* base = sqlite3_vfs_find(nullptr);
    if (base == nullptr) return false;
    static sqlite3_vfs vfs{};
    // Version 2 at most: xCurrentTimeInt64 is the newest method this shim forwards.
    vfs.iVersion = std::min(base->iVersion, 2);
    vfs.szOsFile = static_cast<int>(sizeof(DiskFile)) + base->szOsFile;
    vfs.mxPathname = base->mxPathname;
    vfs.zName = kVfsName;
    vfs.pAppData = base;
    vfs.xOpen = disk_open;
    vfs.xDelete = disk_delete;
    vfs.xAccess = disk_access;
    vfs.xFullPathname = disk_full_pathname;
    vfs.xDlOpen = disk_dl_open;
    vfs.xDlError = disk_dl_error;
    vfs.xDlSym = disk_dl_sym;
    vfs.xDlClose = disk_dl_close;
    vfs.xRandomness = disk_randomness;
    vfs.xSleep = disk_sleep;
    vfs.xCurrentTime = disk_current_time;
    vfs.xGetLastError = disk_get_last_error;
    if (vfs.iVersion >= 2) vfs.xCurrentTimeInt64 = disk_current_time_int64;
    return sqlite3_vfs_register(&vfs, 0) == SQLITE_OK;
  }();
  return registered ? kVfsName : nullptr;  // nullptr: SQLite's default, should registering fail
}

}  // namespace


// ---------------------------------------------------------------------------------------------
// Connection

Connection::Connection(const std::string& path, Open mode, std::string label) : path_(path), label_(std::move(label)) {
  const int flags = mode == Open::create ? SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE : SQLITE_OPEN_READWRITE;
  const int rc = sqlite3_open_v2(path.c_str(), &db_, flags, disk_vfs_name());
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

bool Connection::in_transaction() const noexcept { return sqlite3_get_autocommit(db_) == 0; }

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

Transaction::Transaction(Connection& connection, Lock lock) : connection_(connection) {
  connection_.exec(lock == Lock::write ? "BEGIN IMMEDIATE" : "BEGIN");
}

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

namespace disk_fault {
void set_full(bool full) noexcept { sql::g_room_bytes.store(full ? 0 : sql::kUnlimited, std::memory_order_relaxed); }
void fill_after_bytes(std::int64_t bytes) noexcept {
  sql::g_room_bytes.store(std::clamp<std::int64_t>(bytes, 1, sql::kUnlimited - 1), std::memory_order_relaxed);
}
bool full() noexcept { return sql::g_room_bytes.load(std::memory_order_relaxed) <= 0; }
std::int64_t refused_writes() noexcept { return sql::g_refused_writes.load(std::memory_order_relaxed); }
}  // namespace disk_fault

std::int64_t unix_ms_now() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

}  // namespace imucal::storage
