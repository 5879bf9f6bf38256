// The known word nearest to a misspelt one, for messages that say what was probably meant: a
// command line's subcommands and options, a JSON object's keys.
#pragma once

#include <cstddef>
#include <optional>
#include <string>
#include <vector>

namespace imucal {

// Levenshtein distance: insertions, deletions and substitutions, one each.
std::size_t edit_distance(const std::string& a, const std::string& b);

// The known word nearest to `word` (edit distance at most a third of its length, at least 2), or
// nothing: "calibrat" -> "calibrate", "--dbb" -> "--db", "gravity_mps" -> "gravity_mps2".
std::optional<std::string> nearest_word(const std::string& word, const std::vector<std::string>& known);

}  // namespace imucal
