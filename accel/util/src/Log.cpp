#include "duplex/accel/Log.h"

#include <spdlog/sinks/stdout_sinks.h>
#include <spdlog/spdlog.h>

namespace duplex {

std::shared_ptr<spdlog::logger> logger() {
  // Created once; the registry lets applications find it by name too.
  static std::shared_ptr<spdlog::logger> instance = [] {
    auto existing = spdlog::get("duplex");
    if (existing) return existing;
    auto l = spdlog::stderr_logger_mt("duplex");
    l->set_level(spdlog::level::warn);
    return l;
  }();
  return instance;
}

}  // namespace duplex
