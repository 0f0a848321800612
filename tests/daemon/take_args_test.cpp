// expand_take_args: files as given, takes by name or directory as their raw files in order,
// and a clear refusal for anything else.
#include "daemon/take_args.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "serve/take_store.hpp"

namespace mocap::daemon {
namespace {

namespace fs = std::filesystem;

class TakeArgs : public ::testing::Test {
protected:
    void SetUp() override {
        dir_ = fs::temp_directory_path() / ("mocap_take_args_" + std::to_string(::getpid()));
        fs::remove_all(dir_);
        fs::create_directories(dir_ / "takes");
        serve::TakeStore store((dir_ / "takes").string());
        std::string error;
        for (const char* name : {"walk1", "empty"}) {
            serve::TakeMeta meta;
            meta.name = name;
            ASSERT_TRUE(store.create(meta, &error)) << error;
        }
        // Two raw files, written out of order: the take lists them in recording order.
        std::ofstream(dir_ / "takes/walk1/raw-20261202T120001Z-1.mocapraw") << "b";
        std::ofstream(dir_ / "takes/walk1/raw-20261202T120000Z-0.mocapraw") << "a";
        std::ofstream(dir_ / "loose.mocapraw") << "c";
    }
    void TearDown() override { fs::remove_all(dir_); }

    std::optional<std::vector<std::string>> expand(std::vector<std::string> args, std::string* error) {
        return expand_take_args(args, dir_.string(), error);
    }

    fs::path dir_;
};

TEST_F(TakeArgs, FilesAndTakesByNameOrDirectoryBecomeRawFilesInOrder) {
    std::string error;
    const std::string a = (dir_ / "takes/walk1/raw-20261202T120000Z-0.mocapraw").string();
    const std::string b = (dir_ / "takes/walk1/raw-20261202T120001Z-1.mocapraw").string();
    const std::string loose = (dir_ / "loose.mocapraw").string();
    auto files = expand({loose, "walk1"}, &error);
    ASSERT_TRUE(files) << error;
    EXPECT_EQ(*files, (std::vector<std::string>{loose, a, b}));
    files = expand({(dir_ / "takes/walk1/").string()}, &error);
    ASSERT_TRUE(files) << error;
    EXPECT_EQ(*files, (std::vector<std::string>{a, b}));
}

TEST_F(TakeArgs, AnythingElseIsRefusedByName) {
    std::string error;
    EXPECT_FALSE(expand({"walk2"}, &error));
    EXPECT_NE(error.find("walk2: neither a raw recording file nor a take"), std::string::npos) << error;
    EXPECT_FALSE(expand({"empty"}, &error));
    EXPECT_NE(error.find("empty: take 'empty' has no raw file"), std::string::npos) << error;
    EXPECT_FALSE(expand({"../etc/passwd"}, &error)) << "not a file here, and not a take name";
    EXPECT_FALSE(expand({dir_.string()}, &error)) << "a directory that is not a take";
    EXPECT_NE(error.find("no readable take.json"), std::string::npos) << error;
}

}  // namespace
}  // namespace mocap::daemon
