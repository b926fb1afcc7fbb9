// A GoogleTest fixture base that holds one headless EGL context per test suite.
#pragma once

#include <memory>

#include <gtest/gtest.h>

#include "runtime/gl/egl_context.h"

namespace gimlod::test {

// Base: ::testing::Test, or ::testing::TestWithParam<T> for a parameterized suite.
template <class Base = ::testing::Test>
class GlContextTest : public Base {
 protected:
  static void SetUpTestSuite() { context_ = gl::EglContext::create(); }
  static void TearDownTestSuite() { context_.reset(); }
  static inline std::unique_ptr<gl::EglContext> context_;
};

}  // namespace gimlod::test
