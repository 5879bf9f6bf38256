// The web folder of the source tree this imucald was built from, for a run from the build tree
// (scripts/run.sh); empty when the build gave none. Compiled on its own (daemon/CMakeLists.txt):
// the path is the only text that differs between two clones, and a unity file holding it would
// miss ccache in every clean clone.
#pragma once

namespace imucal::daemon {

const char* source_web_dir();

}  // namespace imucal::daemon
