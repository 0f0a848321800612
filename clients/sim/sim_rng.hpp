// sim_rng.hpp — the simulator's random source, deterministic for a seed on every platform.
//
// std::mt19937_64's output sequence is fixed by the C++ standard, but the distributions
// (std::normal_distribution, ...) are implementation-defined. The simulator therefore draws
// raw 64-bit words and shapes them itself, so a recording generated from seed N is the
// same with any standard library. Thread-safety: one instance per thread. Cost: a few ns.
#pragma once

#include <cmath>
#include <cstdint>
#include <numbers>
#include <random>

namespace mocap::sim {

/// SplitMix64 step: decorrelates derived seeds (seed, stream id) -> independent streams.
inline std::uint64_t splitmix64(std::uint64_t x) {
    x += 0x9E3779B97F4A7C15ull;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
    return x ^ (x >> 31);
}

class SimRng {
public:
    /// stream: independent sub-sequences from one user seed (motion, noise, ...), so that
    /// changing how many numbers one concern draws does not shift the others.
    explicit SimRng(std::uint64_t seed, std::uint64_t stream = 0)
        : engine_(splitmix64(seed ^ splitmix64(stream + 1))) {}

    /// Uniform in [0, 1) with 53 random bits.
    double uniform() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }
    /// Uniform in [lo, hi).
    double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
    /// +1 or -1 with equal probability.
    double sign() { return (engine_() >> 63) != 0 ? 1.0 : -1.0; }

    /// Standard normal (Box–Muller; the second value of each pair is kept for the next call).
    double normal() {
        if (has_spare_) {
            has_spare_ = false;
            return spare_;
        }
        const double u1 = 1.0 - uniform();  // (0, 1]: log stays finite
        const double u2 = uniform();
        const double r = std::sqrt(-2.0 * std::log(u1));
        const double a = 2.0 * std::numbers::pi * u2;
        spare_ = r * std::sin(a);
        has_spare_ = true;
        return r * std::cos(a);
    }

private:
    std::mt19937_64 engine_;
    bool has_spare_ = false;
    double spare_ = 0.0;
};

}  // namespace mocap::sim
