#include "daemon/source_web_dir.hpp"

namespace imucal::daemon {

const char* source_web_dir() {
#ifdef IMUCAL_SOURCE_WEB_DIR
  return IMUCAL_SOURCE_WEB_DIR;
#else
  return "";
#endif
}

}  // namespace imucal::daemon
