// Status, StatusOr, the propagation macros and FACEDYN_CHECK.
#include "core/status.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <memory>
#include <string>

#include "core/check.h"

namespace facedyn {
namespace {

using ::testing::HasSubstr;

StatusOr<int> ParsePositive(int value) {
  if (value <= 0)
    return InvalidArgumentError("value " + std::to_string(value) + " is not positive");
  return value;
}

StatusOr<int> Doubled(int value) {
  FACEDYN_ASSIGN_OR_RETURN(const int positive, ParsePositive(value));
  return 2 * positive;
}

Status CheckBoth(int a, int b) {
  FACEDYN_RETURN_IF_ERROR(ParsePositive(a).status());
  FACEDYN_RETURN_IF_ERROR(ParsePositive(b).status().WithContext("second"));
  return Status::Ok();
}

TEST(Status, DefaultIsOk) {
  const Status ok;
  EXPECT_TRUE(ok.ok());
  EXPECT_EQ(ok.code(), StatusCode::kOk);
  EXPECT_EQ(ok.ToString(), "OK");
  EXPECT_TRUE(Status::Ok().ok());
}

TEST(Status, ErrorConstructorsSetTheCode) {
  EXPECT_EQ(InvalidArgumentError("m").code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(NotFoundError("m").code(), StatusCode::kNotFound);
  EXPECT_EQ(DataLossError("m").code(), StatusCode::kDataLoss);
  EXPECT_EQ(FailedPreconditionError("m").code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(UnavailableError("m").code(), StatusCode::kUnavailable);
  EXPECT_EQ(InternalError("m").code(), StatusCode::kInternal);
  EXPECT_EQ(AbortedError("m").code(), StatusCode::kAborted);
  const Status error = DataLossError("take/positions.pc2: truncated");
  EXPECT_FALSE(error.ok());
  EXPECT_EQ(error.message(), "take/positions.pc2: truncated");
  EXPECT_EQ(error.ToString(), "take/positions.pc2: truncated");
  EXPECT_STREQ(StatusCodeName(StatusCode::kDataLoss), "data loss");
  EXPECT_STREQ(StatusCodeName(StatusCode::kOk), "OK");
}

TEST(StatusWithContext, PrefixesErrorsOnly) {
  const Status error = NotFoundError("no such file");
  const Status wrapped = error.WithContext("take/skull.csv");
  EXPECT_EQ(wrapped.code(), StatusCode::kNotFound);
  EXPECT_EQ(wrapped.message(), "take/skull.csv: no such file");
  EXPECT_TRUE(Status::Ok().WithContext("ignored").ok());
  EXPECT_EQ(Status::Ok().WithContext("ignored").message(), "");
}

TEST(StatusOr, HoldsValueOrError) {
  const StatusOr<std::string> value(std::string("mm"));
  ASSERT_TRUE(value.ok());
  EXPECT_EQ(*value, "mm");
  EXPECT_EQ(value->size(), 2u);
  const StatusOr<std::string> error(NotFoundError("missing"));
  EXPECT_FALSE(error.ok());
  EXPECT_EQ(error.status().message(), "missing");
  // Move-only values move out.
  StatusOr<std::unique_ptr<int>> owned(std::make_unique<int>(5));
  std::unique_ptr<int> taken = std::move(owned).value();
  EXPECT_EQ(*taken, 5);
}

TEST(StatusMacros, PropagateTheFirstError) {
  EXPECT_EQ(*Doubled(21), 42);
  const auto failed = Doubled(-1);
  ASSERT_FALSE(failed.ok());
  EXPECT_EQ(failed.status().message(), "value -1 is not positive");
  EXPECT_TRUE(CheckBoth(1, 2).ok());
  EXPECT_EQ(CheckBoth(0, -2).message(), "value 0 is not positive");
  EXPECT_EQ(CheckBoth(1, -2).message(), "second: value -2 is not positive");
}

TEST(StatusOrDeathTest, ValueOfAnErrorAborts) {
  const StatusOr<int> error(DataLossError("corrupt header"));
  EXPECT_DEATH((void)error.value(), "value\\(\\) on a failed StatusOr: corrupt header");
}

TEST(StatusOrDeathTest, ConstructingFromOkAborts) {
  EXPECT_DEATH((void)StatusOr<int>(Status::Ok()), "OK status without a value");
}

TEST(CheckDeathTest, AbortsWithConditionFileAndMessage) {
  const int frames = 3;
  EXPECT_DEATH(FACEDYN_CHECK(frames == 4, "need " + std::to_string(4) + " frames"),
               "internal check failed at .*status_test.cc:[0-9]+: frames == 4 .* need 4 frames");
}

TEST(Check, PassingCheckDoesNothing) {
  int evaluated = 0;
  FACEDYN_CHECK(++evaluated == 1, "evaluated once");
  EXPECT_EQ(evaluated, 1);
}

}  // namespace
}  // namespace facedyn
