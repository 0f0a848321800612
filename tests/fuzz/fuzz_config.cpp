// Fuzz target: the TOML config loader (server/daemon parse_config).
//
// It must never throw or crash. A rejected text must come with an error of the form
// "<source>:<line>: ..." (line a positive number); an accepted one must parse the same
// way twice (no hidden state).
#include <cctype>
#include <exception>
#include <string>
#include <string_view>

#include "daemon/config.hpp"
#include "fuzz_target.hpp"

MOCAP_FUZZ_ENTRY(config) {
    const std::string_view text(reinterpret_cast<const char*>(data), size);
    std::string error;
    std::optional<mocap::daemon::DaemonConfig> config;
    try {
        config = mocap::daemon::parse_config(text, "fuzz.toml", &error);
    } catch (const std::exception& e) {
        MOCAP_FUZZ_CHECK(false, e.what());
    } catch (...) {
        MOCAP_FUZZ_CHECK(false, "parse_config threw a non-standard exception");
    }
    if (!config) {
        const std::string prefix = "fuzz.toml:";
        MOCAP_FUZZ_CHECK(error.compare(0, prefix.size(), prefix) == 0, error.c_str());
        std::size_t i = prefix.size();
        std::size_t line = 0;
        while (i < error.size() && std::isdigit(static_cast<unsigned char>(error[i]))) {
            line = line * 10 + static_cast<std::size_t>(error[i] - '0');
            ++i;
        }
        MOCAP_FUZZ_CHECK(line > 0 && i < error.size() && error[i] == ':', error.c_str());
        return 0;
    }
    std::string error2;
    const auto again = mocap::daemon::parse_config(text, "fuzz.toml", &error2);
    MOCAP_FUZZ_CHECK(again && *again == *config, "second parse differs");
    return 0;
}
