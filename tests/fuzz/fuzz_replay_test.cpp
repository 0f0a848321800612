// Replays every committed seed (corpus/<target>/) and every input that once crashed a
// fuzz target (regressions/<target>/) through the target's entry function, compiled with
// the project's compiler. A failing check aborts the test binary with its message; a
// sanitizer build (tests/sanitize.sh) adds ASan/UBSan to the replay.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "fuzz_target.hpp"

int mocap_fuzz_wire_stream(const std::uint8_t* data, std::size_t size);
int mocap_fuzz_reassembler(const std::uint8_t* data, std::size_t size);
int mocap_fuzz_client_session(const std::uint8_t* data, std::size_t size);
int mocap_fuzz_config(const std::uint8_t* data, std::size_t size);
int mocap_fuzz_bvh(const std::uint8_t* data, std::size_t size);

namespace {

namespace fs = std::filesystem;
using Entry = int (*)(const std::uint8_t*, std::size_t);

// Returns the number of files replayed from corpus/<target> and regressions/<target>.
std::size_t replay(const std::string& target, Entry entry) {
    std::size_t files = 0;
    for (const char* kind : {"corpus", "regressions"}) {
        const fs::path dir = fs::path(MOCAP_FUZZ_DIR) / kind / target;
        if (!fs::is_directory(dir)) continue;
        std::vector<fs::path> paths;
        for (const auto& e : fs::directory_iterator(dir)) {
            if (e.is_regular_file()) paths.push_back(e.path());
        }
        std::sort(paths.begin(), paths.end());
        for (const fs::path& p : paths) {
            std::ifstream in(p, std::ios::binary);
            const std::vector<char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
            SCOPED_TRACE(p.string());
            std::fprintf(stderr, "replay %s\n", p.c_str());
            // An exactly sized heap copy, as libFuzzer passes it.
            std::vector<std::uint8_t> copy(bytes.begin(), bytes.end());
            EXPECT_EQ(entry(copy.empty() ? nullptr : copy.data(), copy.size()), 0);
            ++files;
        }
    }
    return files;
}

TEST(FuzzReplay, WireStream) {
    EXPECT_GT(replay("wire_stream", mocap_fuzz_wire_stream), 0u);
}
TEST(FuzzReplay, Reassembler) {
    EXPECT_GT(replay("reassembler", mocap_fuzz_reassembler), 0u);
}
TEST(FuzzReplay, ClientSession) {
    EXPECT_GT(replay("client_session", mocap_fuzz_client_session), 0u);
}
TEST(FuzzReplay, Config) {
    EXPECT_GT(replay("config", mocap_fuzz_config), 0u);
}
TEST(FuzzReplay, Bvh) {
    EXPECT_GT(replay("bvh", mocap_fuzz_bvh), 0u);
}

}  // namespace
