// The table's own errors in JSON (formats.md: meta.json's `table`; the daemon's configuration
// holds the same keys beside the table's limits): {"geometry": {...}, "sigma": {...},
// "certificate": "..."}, angles in arc seconds, encoder harmonics [[k, a_arcsec, phi_deg], ...].
// Read strictly (core's ObjectReader, throwing at the first problem with its path): an unknown key
// inside `geometry` or `sigma` is refused, since a term of the table's error that is silently
// dropped is a wrong reference.
#pragma once

#include <string>

#include <nlohmann/json_fwd.hpp>

#include "core/table.hpp"

namespace imucal {
class ObjectReader;
}

namespace imucal::table {

// The keys geometry, sigma and certificate of `r` (others are r's business). Nothing when none
// of the three is there. Throws std::invalid_argument("path: what") at the first problem.
std::optional<TableCertificate> read_table_certificate(ObjectReader& r);
// One `geometry` (or, `is_sigma`, a `sigma`: every value a non-negative 1-sigma) object at `where`.
TableGeometry read_table_geometry(const nlohmann::json& j, const std::string& where, bool is_sigma);

// A file holding the `table` object, or a recording's meta.json (its `table` is taken). Throws
// std::runtime_error naming the file.
TableCertificate read_table_certificate_file(const std::string& path);

nlohmann::ordered_json table_geometry_to_json(const TableGeometry& g);
nlohmann::ordered_json table_certificate_to_json(const TableCertificate& c);

}  // namespace imucal::table
