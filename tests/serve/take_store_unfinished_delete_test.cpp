// The take store's clean-up at start (serve/take_store.hpp, remove_unfinished_deletes): the
// `.deleting-*` folders a delete leaves when the daemon dies between its rename and the
// removal go, and nothing else does, whatever links they hold or are.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "recorder_fixture.hpp"
#include "serve/take_store.hpp"

namespace mocap::serve {
namespace {

using test::TempDir;
namespace fs = std::filesystem;

TEST(TakeStore, FoldersOfDeletesThatDidNotFinishAreRemovedAndNothingElse) {
    TempDir tmp;
    const fs::path root = tmp.path / "takes";
    const fs::path outside = tmp.path / "outside";
    fs::create_directories(outside / "kept");
    std::ofstream(outside / "precious.txt") << "not the store's";

    TakeStore store(root.string());
    TakeMeta m;
    m.name = "walk1";
    m.start_us = 1;
    std::string error;
    ASSERT_TRUE(store.create(m, &error)) << error;
    // Two deletes cut short: one holds a take's files and a link out of the store.
    fs::create_directories(root / ".deleting-walk0-1" / "sub");
    std::ofstream(root / ".deleting-walk0-1" / "raw-0.mocapraw") << "raw";
    fs::create_directory_symlink(outside, root / ".deleting-walk0-1" / "link");
    fs::create_directory(root / ".deleting-x-7");
    // Not ours to remove: a link and a file with that name, another hidden folder.
    fs::create_directory_symlink(outside, root / ".deleting-link-2");
    std::ofstream(root / ".deleting-file-3") << "a file";
    fs::create_directory(root / ".other");

    EXPECT_EQ(store.remove_unfinished_deletes(), 2u);
    EXPECT_FALSE(fs::exists(fs::symlink_status(root / ".deleting-walk0-1")));
    EXPECT_FALSE(fs::exists(root / ".deleting-x-7"));
    EXPECT_TRUE(fs::is_symlink(root / ".deleting-link-2"));
    EXPECT_TRUE(fs::is_regular_file(root / ".deleting-file-3"));
    EXPECT_TRUE(fs::is_directory(root / ".other"));
    EXPECT_TRUE(fs::is_regular_file(outside / "precious.txt")) << "a link is never followed";
    EXPECT_TRUE(fs::is_directory(outside / "kept"));
    ASSERT_EQ(store.list().size(), 1u);
    EXPECT_EQ(store.list().front().meta.name, "walk1");
    EXPECT_EQ(store.remove_unfinished_deletes(), 0u) << "nothing left the second time";
}

TEST(TakeStore, NoTakesDirectoryYetIsNothingToRemove) {
    TempDir tmp;
    TakeStore store((tmp.path / "takes").string());
    EXPECT_EQ(store.remove_unfinished_deletes(), 0u);
    EXPECT_FALSE(fs::exists(tmp.path / "takes"));
}

}  // namespace
}  // namespace mocap::serve
