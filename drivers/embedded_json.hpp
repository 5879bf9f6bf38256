// Built-in descriptions (IMU links, chamber register maps, table dialects) are JSON files compiled
// in as text (drivers/CMakeLists.txt); a configuration names one of them or a file. One rule for
// all three: a built-in name wins, anything else is a path.
#pragma once

#include <span>
#include <string>
#include <vector>

namespace imucal::drivers {

struct EmbeddedJson {
  const char* name;
  const char* json;
};

std::vector<std::string> embedded_names(std::span<const EmbeddedJson> builtins);
// The text of the built-in `name`; std::invalid_argument naming `what` and the built-in names.
std::string embedded_text(std::span<const EmbeddedJson> builtins, const std::string& name, const std::string& what);
// The text of the built-in `name_or_path`, else of the file at that path; std::invalid_argument
// naming `what`, the built-in names and the path when neither exists.
std::string embedded_or_file_text(std::span<const EmbeddedJson> builtins, const std::string& name_or_path,
                                  const std::string& what);

}  // namespace imucal::drivers
