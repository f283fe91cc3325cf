// Status and StatusOr: how data-dependent failures travel (STYLE.md §5).
//
// A corrupt file, a device that did not answer or a singular fit is not a programmer error:
// the function that meets it returns a Status (or a StatusOr<T> carrying either the value or
// the failure) and the caller must look at it ([[nodiscard]]). Messages are written for the
// person at the terminal: they name the file, field, frame or vertex that was wrong. The app
// prints them and exits non-zero; nothing deep in the stack calls exit() or prints.
#pragma once

#include <optional>
#include <string>
#include <utility>

#include "core/check.h"

namespace facedyn {

enum class StatusCode {
  kOk = 0,
  kInvalidArgument,   // bad CLI argument, config field or option value
  kNotFound,          // missing file, device or named item
  kDataLoss,          // truncated or corrupted file
  kFailedPrecondition,  // inputs that disagree with each other (counts, fps, topology)
  kUnavailable,       // a device or link that did not answer
  kInternal,          // a solver or library that failed in a way the input does not explain
  kAborted,           // stopped on request (signal, user)
};

const char* StatusCodeName(StatusCode code);

class [[nodiscard]] Status {
 public:
  Status() = default;  // OK
  Status(StatusCode code, std::string message) : code_(code), message_(std::move(message)) {}

  static Status Ok() { return Status(); }

  bool ok() const { return code_ == StatusCode::kOk; }
  StatusCode code() const { return code_; }
  const std::string& message() const { return message_; }

  // Returns a copy whose message is "<context>: <message>", for adding the file or stage.
  Status WithContext(const std::string& context) const;

  std::string ToString() const;

 private:
  StatusCode code_ = StatusCode::kOk;
  std::string message_;
};

Status InvalidArgumentError(std::string message);
Status NotFoundError(std::string message);
Status DataLossError(std::string message);
Status FailedPreconditionError(std::string message);
Status UnavailableError(std::string message);
Status InternalError(std::string message);
Status AbortedError(std::string message);

template <typename T>
class [[nodiscard]] StatusOr {
 public:
  StatusOr(T value) : value_(std::move(value)) {}  // NOLINT: implicit by design.
  StatusOr(Status status) : status_(std::move(status)) {  // NOLINT: implicit by design.
    FACEDYN_CHECK(!status_.ok(), "StatusOr constructed from an OK status without a value");
  }

  bool ok() const { return status_.ok(); }
  const Status& status() const { return status_; }

  const T& value() const& {
    FACEDYN_CHECK(ok(), "value() on a failed StatusOr: " + status_.ToString());
    return *value_;
  }
  T& value() & {
    FACEDYN_CHECK(ok(), "value() on a failed StatusOr: " + status_.ToString());
    return *value_;
  }
  T&& value() && {
    FACEDYN_CHECK(ok(), "value() on a failed StatusOr: " + status_.ToString());
    return std::move(*value_);
  }
  const T& operator*() const& { return value(); }
  T& operator*() & { return value(); }
  const T* operator->() const { return &value(); }
  T* operator->() { return &value(); }

 private:
  Status status_;
  std::optional<T> value_;
};

}  // namespace facedyn

#define FACEDYN_STATUS_CONCAT_INNER(a, b) a##b
#define FACEDYN_STATUS_CONCAT(a, b) FACEDYN_STATUS_CONCAT_INNER(a, b)

// Returns from the enclosing function if `expr` (a Status) is not OK.
#define FACEDYN_RETURN_IF_ERROR(expr)               \
  do {                                              \
    ::facedyn::Status facedyn_status_ = (expr);     \
    if (!facedyn_status_.ok()) return facedyn_status_; \
  } while (false)

// `lhs = value of expr` (a StatusOr), or returns its status from the enclosing function.
#define FACEDYN_ASSIGN_OR_RETURN(lhs, expr) \
  FACEDYN_ASSIGN_OR_RETURN_IMPL(FACEDYN_STATUS_CONCAT(facedyn_statusor_, __LINE__), lhs, expr)
#define FACEDYN_ASSIGN_OR_RETURN_IMPL(tmp, lhs, expr) \
  auto tmp = (expr);                                  \
  if (!tmp.ok()) return tmp.status();                 \
  lhs = std::move(tmp).value()
