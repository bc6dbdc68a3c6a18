#pragma once
/// \file Error.h
/// Typed exceptions for bad input. Internal invariants are checked separately (DUPLEX_CHECK).

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

}  // namespace duplex
