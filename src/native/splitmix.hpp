// The project's random stream in the compiled core: splitmix64 (Steele, Lea & Flood, "Fast splittable
// pseudorandom number generators", OOPSLA 2014), as the pure-Python CompletionChains uses it, so that
// the same seed gives the same numbers in both.
#pragma once

#include <cstdint>

namespace opportune {

inline std::uint64_t splitmix64(std::uint64_t& state) {
    std::uint64_t z = (state += 0x9E3779B97F4A7C15ULL);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
}

// The next draw's top 53 bits as a double in [0, 1).
inline double uniform53(std::uint64_t& state) { return double(splitmix64(state) >> 11) * (1.0 / 9007199254740992.0); }

}  // namespace opportune
