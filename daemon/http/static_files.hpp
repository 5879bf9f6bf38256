// The browser UI's files (web/) served at `/`: content types by extension, validators and
// caching headers, and no way out of the root (no `..`, no hidden files, no symlink escape).
#pragma once

#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace imucal::daemon {

struct HttpReply {
  int status = 200;
  std::string body;
  std::string content_type = "application/json";
  std::vector<std::pair<std::string, std::string>> headers;
  // When set, the body is this file's content, sent from the disk (large downloads); `body` is
  // then ignored.
  std::string file;
};

class StaticFiles {
 public:
  // `root` need not exist (then every file is 404).
  explicit StaticFiles(const std::string& root);
  const std::string& root() const { return root_; }
  // `path`: the URL path (percent-encoded, without the query). `head`: no body.
  HttpReply get(std::string_view path, std::string_view if_none_match, bool head) const;

 private:
  std::string root_;  // canonical, or empty
};

// Percent-decoding of a URL component; false for malformed escapes or an encoded NUL.
bool percent_decode(std::string_view in, std::string& out, bool plus_is_space = false);

const char* content_type_for(std::string_view path);

}  // namespace imucal::daemon
