#pragma once
/// \file Check.h
/// Checks of internal invariants, after pbrt-v4's CHECK / DCHECK: DUPLEX_CHECK(cond) is always
/// evaluated; DUPLEX_DCHECK(cond) only in debug builds (NDEBUG not defined) and compiles to nothing
/// otherwise, for checks inside hot loops. A failed check is a bug in Duplex, not bad input.
///
/// A failure throws InternalError naming the file, the line and the condition text rather than
/// aborting: Duplex is a library, and its callers (an editor, a long sensor run) may want to save
/// their work or report the bug before they stop, which abort() would not let them do. Bad input is
/// reported with Error and its subclasses (Error.h), never with these checks.

#include "duplex/accel/Error.h"

namespace duplex::check_detail {
/// Throws InternalError("<file>:<line>: internal check failed: <condition>").
[[noreturn]] void fail(const char* file, int line, const char* condition);
}  // namespace duplex::check_detail

/// Throws InternalError with file:line and the condition text when `cond` is false; always checked.
#define DUPLEX_CHECK(cond)                                     \
  do {                                                         \
    if (!(cond)) [[unlikely]]                                  \
      ::duplex::check_detail::fail(__FILE__, __LINE__, #cond); \
  } while (false)

#ifdef NDEBUG
/// Release builds: `cond` is not evaluated (it must compile, so the check cannot rot).
#define DUPLEX_DCHECK(cond)             \
  do {                                  \
    if (false) static_cast<void>(cond); \
  } while (false)
#else
/// Debug builds: DUPLEX_CHECK.
#define DUPLEX_DCHECK(cond) DUPLEX_CHECK(cond)
#endif
