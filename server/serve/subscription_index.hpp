// subscription_index.hpp — which sessions of one serve thread want which subject's frames.
//
// The fan-out walks one subject's list per frame. A (re)subscription costs what the
// client changes, never what other clients subscribed: each subject's list entry is
// found through the client's own record (subject -> position), and removal moves the
// list's last entry into the hole and fixes that entry's one back-reference. The old
// index scanned a subject's whole list to remove one client, so a Subscribe naming S
// subjects that C other clients also named cost S x C on the serve thread (issue 13,
// item 1). Here assign() costs O(old + new) comparisons for the merge and O(1) expected
// per subject actually added or dropped.
//
// Thread-safety: none; each serve thread (lane) owns its index. `Session` is only
// pointed to: the index holds a shared_ptr per client so a session outlives its entries.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <unordered_map>
#include <vector>

namespace mocap::serve {

template <class Session>
class SubscriptionIndex {
public:
    /// Makes `session`'s subscription exactly `subjects` (sorted, unique), or every subject
    /// when `all`. Calls added(subject) / removed(subject) for each subject that changes;
    /// returns +1 / -1 / 0 as the session joins, leaves or stays in the all-subjects list.
    template <class Added, class Removed>
    int assign(const std::shared_ptr<Session>& session, bool all, std::span<const std::uint32_t> subjects,
               Added&& added, Removed&& removed);

    /// Drops every subscription of `session` (calls removed() per subject); returns -1 if
    /// it was in the all-subjects list, else 0. No-op for an unknown session.
    template <class Removed>
    int remove(const Session* session, Removed&& removed);

    /// Calls f(Session&) for every session subscribed to `subject`, then for every
    /// all-subjects session. f must not change the index.
    template <class F>
    void for_each(std::uint32_t subject, F&& f) const;

    [[nodiscard]] std::size_t clients() const { return clients_.size(); }
    /// Subjects with at least one subscriber (the map never keeps empty lists).
    [[nodiscard]] std::size_t subjects() const { return by_subject_.size(); }
    [[nodiscard]] std::size_t subscribers(std::uint32_t subject) const {
        const auto it = by_subject_.find(subject);
        return it == by_subject_.end() ? 0 : it->second.size();
    }
    [[nodiscard]] std::size_t all_subject_clients() const { return all_.size(); }

private:
    struct Link {
        std::uint32_t subject;
        std::uint32_t position;  ///< index of this client's entry in by_subject_[subject]
    };
    struct Client {
        std::shared_ptr<Session> session;
        std::vector<Link> links;  ///< sorted by subject
        bool all = false;
        std::uint32_t all_position = 0;  ///< index in all_ when `all`
    };

    void link(Client& client, std::uint32_t subject, std::vector<Link>& out);
    void unlink(std::uint32_t subject, std::uint32_t position);
    void leave_all(Client& client);
    static Link* find_link(Client& client, std::uint32_t subject);

    std::unordered_map<const Session*, Client> clients_;
    std::unordered_map<std::uint32_t, std::vector<Session*>> by_subject_;
    std::vector<Session*> all_;
};

template <class Session>
template <class Added, class Removed>
int SubscriptionIndex<Session>::assign(const std::shared_ptr<Session>& session, bool all,
                                       std::span<const std::uint32_t> subjects, Added&& added, Removed&& removed) {
    Client& client = clients_[session.get()];
    client.session = session;
    int all_change = 0;
    if (all && !client.all) {
        client.all = true;
        client.all_position = static_cast<std::uint32_t>(all_.size());
        all_.push_back(session.get());
        all_change = 1;
    } else if (!all && client.all) {
        leave_all(client);
        all_change = -1;
    }
    if (all) subjects = {};
    // Merge the sorted old links with the sorted new subjects: keep, drop or add each.
    std::vector<Link> next;
    next.reserve(subjects.size());
    auto old_it = client.links.begin();
    auto new_it = subjects.begin();
    while (old_it != client.links.end() || new_it != subjects.end()) {
        if (new_it == subjects.end() || (old_it != client.links.end() && old_it->subject < *new_it)) {
            unlink(old_it->subject, old_it->position);
            removed(old_it->subject);
            ++old_it;
        } else if (old_it == client.links.end() || *new_it < old_it->subject) {
            link(client, *new_it, next);
            added(*new_it);
            ++new_it;
        } else {
            next.push_back(*old_it);
            ++old_it;
            ++new_it;
        }
    }
    client.links = std::move(next);
    return all_change;
}

template <class Session>
template <class Removed>
int SubscriptionIndex<Session>::remove(const Session* session, Removed&& removed) {
    const auto it = clients_.find(session);
    if (it == clients_.end()) return 0;
    Client& client = it->second;
    const int all_change = client.all ? -1 : 0;
    if (client.all) leave_all(client);
    for (const Link& l : client.links) {
        unlink(l.subject, l.position);
        removed(l.subject);
    }
    clients_.erase(it);  // releases the index's reference to the session last
    return all_change;
}

template <class Session>
template <class F>
void SubscriptionIndex<Session>::for_each(std::uint32_t subject, F&& f) const {
    if (const auto it = by_subject_.find(subject); it != by_subject_.end()) {
        for (Session* s : it->second)
            f(*s);
    }
    for (Session* s : all_)
        f(*s);
}

template <class Session>
void SubscriptionIndex<Session>::link(Client& client, std::uint32_t subject, std::vector<Link>& out) {
    std::vector<Session*>& list = by_subject_[subject];
    out.push_back({subject, static_cast<std::uint32_t>(list.size())});
    list.push_back(client.session.get());
}

template <class Session>
void SubscriptionIndex<Session>::unlink(std::uint32_t subject, std::uint32_t position) {
    const auto it = by_subject_.find(subject);
    std::vector<Session*>& list = it->second;
    if (position + 1 != list.size()) {
        // Move the last entry into the hole and point its client's link at the new place.
        Session* moved = list.back();
        list[position] = moved;
        find_link(clients_.find(moved)->second, subject)->position = position;
    }
    list.pop_back();
    if (list.empty()) by_subject_.erase(it);  // subjects named once and dropped leave nothing behind
}

template <class Session>
void SubscriptionIndex<Session>::leave_all(Client& client) {
    if (client.all_position + 1 != all_.size()) {
        Session* moved = all_.back();
        all_[client.all_position] = moved;
        clients_.find(moved)->second.all_position = client.all_position;
    }
    all_.pop_back();
    client.all = false;
}

template <class Session>
typename SubscriptionIndex<Session>::Link* SubscriptionIndex<Session>::find_link(Client& client,
                                                                                 std::uint32_t subject) {
    const auto it = std::lower_bound(client.links.begin(), client.links.end(), subject,
                                     [](const Link& l, std::uint32_t s) { return l.subject < s; });
    return &*it;
}

}  // namespace mocap::serve
