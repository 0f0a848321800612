// The take store (serve/take_store.hpp): names that cannot leave the root, the sidecar's
// JSON, the atomic replacement, listing, and deletion (refused while recording).
#include "serve/take_store.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "recorder_fixture.hpp"

namespace mocap::serve {
namespace {

using test::TempDir;
namespace fs = std::filesystem;

TakeMeta meta(const std::string& name, std::int64_t start_us) {
    TakeMeta m;
    m.name = name;
    m.start_us = start_us;
    m.filter = "mocap";
    m.notes = "walk, then \"jump\"\nsecond line";
    return m;
}

void write_text(const fs::path& path, const std::string& text) {
    std::ofstream(path) << text;
}

TEST(TakeName, OnlyOnePathComponentOfSafeCharacters) {
    const std::vector<std::string> good{"a", "walk_01", "Take-2026.12.02", "0", std::string(64, 'x')};
    for (const std::string& name : good)
        EXPECT_TRUE(valid_take_name(name)) << name;
    const std::vector<std::string> bad{"",      ".",       "..",    "../etc", "a/b",
                                       "/abs",  ".hidden", "-dash", "_under", "a b",
                                       "a%2Fb", "a\\b",    "tab\t", "é",      std::string(65, 'x')};
    for (const std::string& name : bad)
        EXPECT_FALSE(valid_take_name(name)) << name;
    EXPECT_FALSE(valid_take_name(std::string_view("a\0b", 3)));
}

TEST(TakeJson, RoundTripsEveryField) {
    TakeMeta m = meta("walk", 1'796'227'835'134'329);
    m.stop_us = m.start_us + 3'021'045;
    m.subjects = {1, 7};
    m.calibration = {"calibration-subject-1.toml"};
    m.samples = 4515;
    m.samples_lost = 3;
    const std::string text = encode_take_json(m);
    EXPECT_NE(text.find("\"start\": \"2026-12-02T16:10:35.134329Z\""), std::string::npos) << text;
    std::string error;
    const auto back = decode_take_json(text, &error);
    ASSERT_TRUE(back) << error;
    EXPECT_EQ(*back, m);
}

TEST(TakeJson, RefusesWhatIsNotASidecar) {
    std::string error;
    EXPECT_FALSE(decode_take_json("", &error));
    EXPECT_FALSE(decode_take_json("[1]", &error));
    EXPECT_FALSE(decode_take_json(R"({"name": 3, "start_us": 1})", &error));
    EXPECT_FALSE(decode_take_json(R"({"name": "../x", "start_us": 1})", &error));
    EXPECT_EQ(error, "invalid take name");
    EXPECT_FALSE(decode_take_json(R"({"name": "ok", "start_us": "soon"})", &error));
    EXPECT_FALSE(decode_take_json(R"({"name": "ok", "start_us": 1, "subjects": [-1]})", &error));
}

TEST(AtomicWrite, ReplacesTheWholeFileAndLeavesNoTemporary) {
    TempDir dir;
    const std::string path = dir.file("take.json");
    write_text(path, "old version, longer than the new one\n");
    ASSERT_EQ(write_file_atomically(path, "new\n"), 0);
    std::ifstream in(path);
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    EXPECT_EQ(text, "new\n");
    EXPECT_FALSE(fs::exists(path + ".tmp"));
    // A directory that is gone: an error, and nothing half written.
    EXPECT_EQ(write_file_atomically(dir.file("missing/take.json"), "x"), ENOENT);
}

TEST(AtomicWrite, AFailedRenameKeepsWhatWasThereAndLeavesNoTemporary) {
    TempDir dir;
    // The target is a directory: the rename fails after the temporary file was written.
    const std::string path = dir.file("take.json");
    fs::create_directories(fs::path(path) / "inside");
    EXPECT_NE(write_file_atomically(path, "new\n"), 0);
    EXPECT_TRUE(fs::exists(fs::path(path) / "inside"));
    EXPECT_FALSE(fs::exists(path + ".tmp"));
}

TEST(TakeStore, CreatesListsInStartOrderAndFinds) {
    TempDir dir;
    TakeStore store(dir.file("takes"));
    std::string error;
    ASSERT_TRUE(store.create(meta("second", 2000), &error)) << error;
    ASSERT_TRUE(store.create(meta("first", 1000), &error)) << error;
    EXPECT_FALSE(store.create(meta("first", 3000), &error));
    EXPECT_EQ(error, "take 'first' exists");
    EXPECT_FALSE(store.create(meta("../escape", 1), &error));
    EXPECT_FALSE(fs::exists(dir.file("escape")));
    write_text(store.dir("first") + "/raw-20261202-161035-0.mocapraw", "MOCAPRAW");

    // Not takes: a hidden directory, a directory without a sidecar, a stray file.
    fs::create_directories(store.root() + "/.deleting-old-1");
    write_text(store.root() + "/.deleting-old-1/take.json", encode_take_json(meta("old", 5)));
    fs::create_directories(store.root() + "/nosidecar");
    write_text(store.root() + "/stray.txt", "x");

    const auto list = store.list();
    ASSERT_EQ(list.size(), 2u);
    EXPECT_EQ(list[0].meta.name, "first");
    EXPECT_EQ(list[0].meta.notes, "walk, then \"jump\"\nsecond line");
    EXPECT_EQ(list[0].raw_bytes, 8u);
    ASSERT_EQ(list[0].raw_files.size(), 1u);
    EXPECT_EQ(list[1].meta.name, "second");
    EXPECT_TRUE(list[1].raw_files.empty());
    EXPECT_TRUE(store.find("second"));
    EXPECT_FALSE(store.find("nosidecar"));
    EXPECT_FALSE(store.find(".deleting-old-1"));
    EXPECT_FALSE(store.find(".."));
}

TEST(TakeStore, SaveReplacesTheSidecar) {
    TempDir dir;
    TakeStore store(dir.file("takes"));
    std::string error;
    TakeMeta m = meta("t", 10);
    ASSERT_TRUE(store.create(m, &error)) << error;
    EXPECT_EQ(store.find("t")->meta.stop_us, 0);
    m.stop_us = 20;
    m.subjects = {3};
    ASSERT_TRUE(store.save(m, &error)) << error;
    EXPECT_EQ(store.find("t")->meta, m);
}

TEST(TakeStore, DeleteRemovesEverythingButNotTheTakeBeingRecorded) {
    TempDir dir;
    TakeStore store(dir.file("takes"));
    std::string error;
    ASSERT_TRUE(store.create(meta("a", 1), &error)) << error;
    ASSERT_TRUE(store.create(meta("b", 2), &error)) << error;
    store.mark_recording("b");
    EXPECT_TRUE(store.find("b")->recording);
    EXPECT_EQ(store.remove("b", &error), TakeStore::Removal::kRecording);
    EXPECT_TRUE(fs::exists(store.dir("b")));
    store.mark_recording("");
    EXPECT_EQ(store.remove("b", &error), TakeStore::Removal::kRemoved);
    EXPECT_EQ(store.remove("b", &error), TakeStore::Removal::kNotFound);
    EXPECT_EQ(store.remove("..", &error), TakeStore::Removal::kNotFound);
    EXPECT_TRUE(fs::exists(dir.path / "takes"));

    // A file opened before the delete stays readable to the end.
    write_text(store.dir("a") + "/raw-x-0.mocapraw", "MOCAPRAW+records");
    std::ifstream open_download(store.dir("a") + "/raw-x-0.mocapraw");
    EXPECT_EQ(store.remove("a", &error), TakeStore::Removal::kRemoved);
    std::string text((std::istreambuf_iterator<char>(open_download)), std::istreambuf_iterator<char>());
    EXPECT_EQ(text, "MOCAPRAW+records");
    EXPECT_TRUE(store.list().empty());
    EXPECT_TRUE(fs::is_empty(dir.path / "takes"));
}

}  // namespace
}  // namespace mocap::serve
