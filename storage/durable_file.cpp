#include "storage/durable_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>

namespace imucal::storage {

namespace {

[[noreturn]] void fail(const std::string& doing, const std::string& path, int error) {
  throw FileError("cannot " + doing + " " + path + ": " + std::strerror(error), error);
}

// A descriptor closed when it goes.
class Descriptor {
 public:
  Descriptor(const std::string& path, int flags, mode_t mode) : fd_(::open(path.c_str(), flags | O_CLOEXEC, mode)) {}
  ~Descriptor() {
    if (fd_ >= 0) ::close(fd_);
  }
  Descriptor(const Descriptor&) = delete;
  Descriptor& operator=(const Descriptor&) = delete;
  int fd() const { return fd_; }

 private:
  int fd_;
};

void write_all(int fd, const std::string& text, const std::string& path) {
  std::size_t done = 0;
  while (done < text.size()) {
    const ssize_t n = ::write(fd, text.data() + done, text.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) fail("write", path, errno);
    done += static_cast<std::size_t>(n);
  }
}

// The rename of a replaced file is durable only once its directory is.
void sync_directory_of(const std::string& path) {
  const std::string dir = std::filesystem::path(path).parent_path().string();
  const Descriptor directory(dir.empty() ? "." : dir, O_RDONLY | O_DIRECTORY, 0);
  if (directory.fd() >= 0) (void)::fsync(directory.fd());
}

}  // namespace

void replace_file_durably(const std::string& path, const std::string& text, bool owner_only) {
  const std::string tmp = path + ".tmp";
  {
    const Descriptor file(tmp, O_WRONLY | O_CREAT | O_TRUNC, owner_only ? 0600 : 0644);
    if (file.fd() < 0) fail("create", tmp, errno);
    write_all(file.fd(), text, tmp);
    if (::fsync(file.fd()) != 0) fail("sync", tmp, errno);
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) fail("rename " + tmp + " onto", path, errno);
  sync_directory_of(path);
}

void append_durably(const std::string& path, const std::string& text) {
  const Descriptor file(path, O_WRONLY | O_APPEND | O_CREAT, 0600);
  if (file.fd() < 0) fail("open", path, errno);
  struct stat before {};
  const bool sized = ::fstat(file.fd(), &before) == 0;
  try {
    write_all(file.fd(), text, path);
  } catch (const FileError&) {
    if (sized) (void)::ftruncate(file.fd(), before.st_size);  // no half line in front of the next
    throw;
  }
  if (::fsync(file.fd()) != 0) fail("sync", path, errno);
}

}  // namespace imucal::storage
