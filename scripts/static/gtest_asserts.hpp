// For the static check only (tests/.clang-tidy passes it with -include; the build never sees it):
// GoogleTest's ASSERT_TRUE, as clang-tidy 16's bugprone-unchecked-optional-access can follow it.
// gtest's own expansion passes the condition through a testing::AssertionResult, whose bool the
// analysis cannot relate to the optional, so `ASSERT_TRUE(opt.has_value()); opt->x` was a finding
// in every test that checks before it looks. Here the condition is tested by the `if` itself; the
// failure is gtest's own (a fatal failure naming the condition, `<< message` appended as usual).
#pragma once

#define GTEST_DONT_DEFINE_ASSERT_TRUE 1
#include <gtest/gtest.h>

#define ASSERT_TRUE(condition)              \
  GTEST_AMBIGUOUS_ELSE_BLOCKER_             \
  if (static_cast<bool>(condition))         \
    ;                                       \
  else                                      \
    GTEST_FATAL_FAILURE_("Value of: " #condition "\n  Actual: false\nExpected: true")
