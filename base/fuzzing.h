// Fuzzing builds (fuzz/, configured with -DMT_FUZZ=ON, which defines the conventional
// FUZZING_BUILD_MODE_UNSAFE_FOR_PRODUCTION) accept any stored checksum, so a fuzzer, which cannot
// forge an XXH64, reaches the parsers behind the checksums: they must hold on any bytes too. Every
// other build checks them.
#pragma once

namespace mt {

#ifdef FUZZING_BUILD_MODE_UNSAFE_FOR_PRODUCTION
constexpr bool kChecksumsChecked = false;
#else
constexpr bool kChecksumsChecked = true;
#endif

}  // namespace mt
