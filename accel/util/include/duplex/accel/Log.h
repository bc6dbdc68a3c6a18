#pragma once
/// \file Log.h
/// The library's one spdlog logger, named "duplex". Quiet by default (level warn); never used per ray.

#include <spdlog/logger.h>

#include <memory>

namespace duplex {

/// The shared logger; thread-safe. Applications may change its level or sinks.
std::shared_ptr<spdlog::logger> logger();

}  // namespace duplex
