// The certificate numbers' sequence of a stand alone (issue 17; the SQLite registry takes its
// numbers from it, registry/sqlite_registry.hpp; a lab's PostgreSQL registry has a database
// sequence instead). It lives in a small file of its own, outside the data directory: a lab that
// starts a new data directory keeps counting. The file is replaced atomically (temporary file,
// fsync, rename: storage/durable_file.hpp) under an exclusive lock, so two daemons sharing it
// never take the same number.
#pragma once

#include <cstdint>
#include <mutex>
#include <string>

namespace imucal::daemon {

class CertificateSequence {
 public:
  // `path`: the sequence file (certificate_sequence_path). Nothing is read until next().
  explicit CertificateSequence(std::string path);

  // Takes the next number: one more than the larger of the file's last number and `floor` (the
  // highest this daemon's database has issued, so that a sequence file restored from an old
  // backup cannot hand out a number again). Throws std::runtime_error naming the file when it
  // cannot be read or written: a certificate without a safe number is not issued. A crash
  // between taking a number and recording it leaves a gap, never a repeat.
  std::int64_t next(std::int64_t floor);
  // The last number taken (0 when the file does not exist yet).
  std::int64_t last() const;
  const std::string& path() const { return path_; }

 private:
  std::int64_t read_last() const;
  std::string path_;
  mutable std::mutex mutex_;  // one taker at a time in this process; the file lock for the rest
};

}  // namespace imucal::daemon
