// Small files that must survive a crash whole (the certificate sequence, the registry's limits
// file, the registry's journal): the one place their bytes reach the disk. A replaced file is
// written beside itself, synced, renamed over the old one and its directory synced: a crash leaves
// the old file or the new one, complete, and the new one stays once the call returns. An appended
// line is synced before the call returns, and cut back on a failure (no half line before the next).
#pragma once

#include <string>

#include "storage/sqlite.hpp"  // StorageError

namespace imucal::storage {

// A failure of one of these files: what was done, the file, and the system's errno.
class FileError : public StorageError {
 public:
  FileError(const std::string& what, int error) : StorageError(what), error_(error) {}
  int error() const noexcept { return error_; }

 private:
  int error_;
};

// Replaces `path` with `text` (through `path`.tmp; one writer at a time is the caller's rule),
// the new file readable by its owner only when `owner_only` (one that may name people).
void replace_file_durably(const std::string& path, const std::string& text, bool owner_only = false);
// Appends `text` to `path` (created 0600 when missing: these files may name people) and syncs it.
void append_durably(const std::string& path, const std::string& text);

}  // namespace imucal::storage
