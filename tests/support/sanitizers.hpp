#pragma once

/// TIGERLOD_SANITIZED is 1 in a build under AddressSanitizer or
/// ThreadSanitizer, with GCC (which defines __SANITIZE_ADDRESS__ and
/// __SANITIZE_THREAD__) or Clang (which, up to version 15, says so only
/// through __has_feature), else 0. Tests that run a large case only to
/// look at results use it to run a smaller one of the same code there: the
/// sanitizers look for memory and thread faults, which that code shows on
/// any input, and the dev pass runs the large case.
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define TIGERLOD_SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
#define TIGERLOD_SANITIZED 1
#endif
#endif
#ifndef TIGERLOD_SANITIZED
#define TIGERLOD_SANITIZED 0
#endif
