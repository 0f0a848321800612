// SubscriptionIndex: membership after every kind of change, O(1) removal bookkeeping
// (positions stay consistent when entries move), and cost proportional to what changes.
#include "serve/subscription_index.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <memory>
#include <random>
#include <set>
#include <vector>

namespace mocap::serve {
namespace {

struct FakeSession {
    int id = 0;
};

using Index = SubscriptionIndex<FakeSession>;

std::vector<int> members(const Index& index, std::uint32_t subject) {
    std::vector<int> ids;
    index.for_each(subject, [&](FakeSession& s) { ids.push_back(s.id); });
    std::sort(ids.begin(), ids.end());
    return ids;
}

struct Changes {
    std::vector<std::uint32_t> added, removed;
    auto on_added() {
        return [this](std::uint32_t s) { added.push_back(s); };
    }
    auto on_removed() {
        return [this](std::uint32_t s) { removed.push_back(s); };
    }
};

TEST(SubscriptionIndex, AssignReportsOnlyWhatChanges) {
    Index index;
    auto a = std::make_shared<FakeSession>(FakeSession{1});
    std::vector<std::uint32_t> first{1, 2, 3};
    Changes c1;
    EXPECT_EQ(index.assign(a, false, first, c1.on_added(), c1.on_removed()), 0);
    EXPECT_EQ(c1.added, (std::vector<std::uint32_t>{1, 2, 3}));
    EXPECT_TRUE(c1.removed.empty());

    Changes same;  // re-sending the same Subscribe changes nothing
    index.assign(a, false, first, same.on_added(), same.on_removed());
    EXPECT_TRUE(same.added.empty());
    EXPECT_TRUE(same.removed.empty());

    std::vector<std::uint32_t> second{2, 3, 4};
    Changes c2;
    index.assign(a, false, second, c2.on_added(), c2.on_removed());
    EXPECT_EQ(c2.added, (std::vector<std::uint32_t>{4}));
    EXPECT_EQ(c2.removed, (std::vector<std::uint32_t>{1}));
    EXPECT_EQ(members(index, 1), std::vector<int>{});
    EXPECT_EQ(members(index, 4), std::vector<int>{1});
    EXPECT_EQ(index.subjects(), 3u);  // subject 1's empty list is gone

    Changes to_all;  // all subjects: the named ones are dropped, the client joins the all list
    EXPECT_EQ(index.assign(a, true, {}, to_all.on_added(), to_all.on_removed()), 1);
    EXPECT_EQ(to_all.removed, (std::vector<std::uint32_t>{2, 3, 4}));
    EXPECT_EQ(members(index, 99), std::vector<int>{1});
    EXPECT_EQ(index.subjects(), 0u);
    Changes back;
    EXPECT_EQ(index.assign(a, false, first, back.on_added(), back.on_removed()), -1);
    EXPECT_EQ(index.all_subject_clients(), 0u);

    Changes gone;
    EXPECT_EQ(index.remove(a.get(), gone.on_removed()), 0);
    EXPECT_EQ(gone.removed, (std::vector<std::uint32_t>{1, 2, 3}));
    EXPECT_EQ(index.clients(), 0u);
    EXPECT_EQ(index.subjects(), 0u);
    EXPECT_EQ(a.use_count(), 1) << "the index released its reference";
}

// Random subscribe/resubscribe/remove against a plain model: whatever moves inside the
// lists, every subject lists exactly the clients that named it.
TEST(SubscriptionIndex, MatchesAModelUnderRandomChurn) {
    constexpr int kClients = 24;
    constexpr std::uint32_t kSubjects = 40;
    Index index;
    std::vector<std::shared_ptr<FakeSession>> sessions;
    std::vector<std::set<std::uint32_t>> model(kClients);
    std::vector<bool> all(kClients, false), present(kClients, false);
    for (int i = 0; i < kClients; ++i)
        sessions.push_back(std::make_shared<FakeSession>(FakeSession{i}));
    std::mt19937 rng(7);
    auto noop = [](std::uint32_t) {};
    for (int step = 0; step < 4000; ++step) {
        const int c = static_cast<int>(rng() % kClients);
        const unsigned op = rng() % 10;
        if (op == 0) {
            index.remove(sessions[c].get(), noop);
            model[c].clear();
            all[c] = present[c] = false;
        } else if (op == 1) {
            index.assign(sessions[c], true, {}, noop, noop);
            model[c].clear();
            all[c] = present[c] = true;
        } else {
            std::set<std::uint32_t> want;
            const unsigned n = rng() % 12;
            for (unsigned k = 0; k < n; ++k)
                want.insert(rng() % kSubjects);
            const std::vector<std::uint32_t> sorted(want.begin(), want.end());
            index.assign(sessions[c], false, sorted, noop, noop);
            model[c] = want;
            all[c] = false;
            present[c] = true;
        }
        if (step % 50 != 0) continue;
        for (std::uint32_t s = 0; s < kSubjects; ++s) {
            std::vector<int> expected;
            for (int i = 0; i < kClients; ++i) {
                if (all[i] || model[i].count(s)) expected.push_back(i);
            }
            ASSERT_EQ(members(index, s), expected) << "subject " << s << " at step " << step;
        }
        ASSERT_EQ(index.clients(), static_cast<std::size_t>(std::count(present.begin(), present.end(), true)));
    }
}

// The cost of one client's change does not depend on how many other clients share its
// subjects: removing a client from 4096 subjects that 300 others also named visits its own
// 4096 entries (counted through the removed() callback), not 300 x 4096.
TEST(SubscriptionIndex, ResubscribingTouchesOnlyTheClientsOwnEntries) {
    Index index;
    std::vector<std::uint32_t> subjects(4096);
    for (std::uint32_t i = 0; i < subjects.size(); ++i)
        subjects[i] = i;
    auto noop = [](std::uint32_t) {};
    std::vector<std::shared_ptr<FakeSession>> others;
    for (int i = 0; i < 300; ++i) {
        others.push_back(std::make_shared<FakeSession>(FakeSession{i}));
        index.assign(others.back(), false, subjects, noop, noop);
    }
    auto churner = std::make_shared<FakeSession>(FakeSession{1000});
    std::size_t changes = 0;
    auto count = [&](std::uint32_t) { ++changes; };
    index.assign(churner, false, subjects, count, count);
    EXPECT_EQ(changes, 4096u);
    changes = 0;
    index.assign(churner, false, subjects, count, count);  // the same again: nothing changes
    EXPECT_EQ(changes, 0u);
    index.remove(churner.get(), count);
    EXPECT_EQ(changes, 4096u);
    EXPECT_EQ(index.subscribers(17), 300u);
    EXPECT_EQ(members(index, 4095).size(), 300u);
}

}  // namespace
}  // namespace mocap::serve
