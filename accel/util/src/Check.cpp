#include "duplex/accel/Check.h"

#include <string>

namespace duplex::check_detail {

void fail(const char* file, int line, const char* condition) {
  throw InternalError(std::string(file) + ":" + std::to_string(line) + ": internal check failed: " + condition);
}

}  // namespace duplex::check_detail
