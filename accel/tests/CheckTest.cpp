// DUPLEX_CHECK / DUPLEX_DCHECK: a failed check throws InternalError naming file:line and the
// condition; DCHECK is evaluated only in debug builds.

#include "duplex/accel/Check.h"

#include <gtest/gtest.h>

#include <string>

namespace duplex {
namespace {

TEST(Check, PassingCheckDoesNothing) {
  int evaluated = 0;
  EXPECT_NO_THROW(DUPLEX_CHECK(++evaluated == 1));
  EXPECT_EQ(evaluated, 1);
}

TEST(Check, FailingCheckThrowsWithFileLineAndCondition) {
  const int two = 2;
  int line = 0;
  try {
    line = __LINE__ + 1;
    DUPLEX_CHECK(two + two == 5);
    FAIL() << "DUPLEX_CHECK(false) did not throw";
  } catch (const InternalError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("CheckTest.cpp:" + std::to_string(line) + ":"), std::string::npos) << what;
    EXPECT_NE(what.find("two + two == 5"), std::string::npos) << what;
  }
}

TEST(Check, InternalErrorIsNotAnInputError) {
  // Code that reports bad input (catch Error) must not swallow a bug.
  bool caught_as_error = false;
  try {
    DUPLEX_CHECK(false);
  } catch (const Error&) {
    caught_as_error = true;
  } catch (const InternalError&) {
  }
  EXPECT_FALSE(caught_as_error);
}

TEST(Check, DcheckFollowsNdebug) {
  int evaluated = 0;
#ifdef NDEBUG
  EXPECT_NO_THROW(DUPLEX_DCHECK(++evaluated < 0));
  EXPECT_EQ(evaluated, 0);  // not evaluated at all
#else
  EXPECT_THROW(DUPLEX_DCHECK(++evaluated < 0), InternalError);
  EXPECT_EQ(evaluated, 1);
#endif
}

}  // namespace
}  // namespace duplex
