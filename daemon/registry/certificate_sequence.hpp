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

  // A number and the time its certificate states it was issued (Unix ms).
  struct Taken {
    std::int64_t number = 0;
    std::int64_t issued_ms = 0;
  };
  // Takes the next number: one more than the larger of the file's last number and `floor` (the
  // highest this daemon's database has issued, so that a sequence file restored from an old
  // backup cannot hand out a number again). Its time is `now_ms`, or the last number's time when
  // that is later, taken in the same step under the file's lock: a later number never states an
  // earlier issue, whichever daemon sharing the file took it and however its clock stands.
  // Throws std::runtime_error naming the file when it cannot be read or written: a certificate
  // without a safe number is not issued. A crash between taking a number and recording it leaves
  // a gap, never a repeat.
  Taken take(std::int64_t floor, std::int64_t now_ms);
  // The last number taken (0 when the file does not exist yet).
  std::int64_t last() const;
  const std::string& path() const { return path_; }

 private:
  Taken read_last() const;
  std::string path_;
  mutable std::mutex mutex_;  // one taker at a time in this process; the file lock for the rest
};

}  // namespace imucal::daemon
