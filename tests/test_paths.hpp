// Where a test finds the source tree, its data, its scratch folder and the programs it starts.
// The paths are compiled into one small generated file per test executable (imucal_add_test in
// tests/CMakeLists.txt), not into the tests' own unity files: an absolute path in a translation
// unit's text makes a clean clone in another folder (CI's) miss every ccache entry of that unit.
#pragma once

#include <string>
#include <string_view>

namespace imucaltest {

const std::string& source_dir();     // the checkout
const std::string& test_data_dir();  // tests/data
const std::string& test_tmp_dir();   // build/<preset>/test-tmp: scratch files
// A program the executable was built with (imucal_add_test's PROGRAMS: "imucald", "imucal",
// "storage_crash_writer"); std::logic_error naming it when it was not given.
const std::string& program(std::string_view name);

}  // namespace imucaltest
