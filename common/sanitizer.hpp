// Whether this translation unit is built with AddressSanitizer (g++: __SANITIZE_ADDRESS__;
// clang: __has_feature(address_sanitizer)). Code that limits its own address space
// (RLIMIT_AS for a reader child) must not do so under ASan, whose shadow memory reserves
// terabytes of it: such code watches resident memory instead.
#pragma once

namespace st {

#if defined(__SANITIZE_ADDRESS__)
inline constexpr bool kAddressSanitizer = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
inline constexpr bool kAddressSanitizer = true;
#else
inline constexpr bool kAddressSanitizer = false;
#endif
#else
inline constexpr bool kAddressSanitizer = false;
#endif

}  // namespace st
