#pragma once
/// \file Error.h
/// Typed exceptions: Error and its subclasses for bad input; InternalError for a broken internal
/// invariant (thrown by DUPLEX_CHECK / DUPLEX_DCHECK, Check.h).

#include <stdexcept>
#include <string>

namespace duplex {

/// Bad input from a user or a file: the message names the file/object and the problem.
class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Bad argument to a library call (wrong sizes, out-of-range ids, NaN transforms).
class InvalidArgument : public Error {
 public:
  using Error::Error;
};

/// A file that cannot be read or is malformed.
class FileError : public Error {
 public:
  using Error::Error;
};

/// A broken internal invariant: a bug in Duplex, whatever the input. Deliberately not an Error, so
/// that code which handles bad input (catch (const Error&)) does not take it for one.
class InternalError : public std::logic_error {
 public:
  using std::logic_error::logic_error;
};

}  // namespace duplex
