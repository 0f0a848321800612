#include "cluster/raw_take_reader.hpp"

#include <nats/nats.h>

#include "cluster/raw_stream.hpp"

namespace mocap::cluster {

RawTakeReader::RawTakeReader(ClusterConfig connection, RawTakeQuery query)
    : connection_(std::move(connection)), query_(query), subject_(raw_subject(connection_.site, query_.subject_id)) {}

RawTakeReader::~RawTakeReader() {
    close();
}

void RawTakeReader::close() {
    if (sub_ != nullptr) {
        (void)natsSubscription_Unsubscribe(sub_);  // the ephemeral consumer goes with it
        natsSubscription_Destroy(sub_);
        sub_ = nullptr;
    }
    if (js_ != nullptr) {
        jsCtx_Destroy(js_);
        js_ = nullptr;
    }
    if (nc_ != nullptr) {
        natsConnection_Close(nc_);
        natsConnection_Destroy(nc_);
        nc_ = nullptr;
    }
    if (options_ != nullptr) {
        natsOptions_Destroy(options_);
        options_ = nullptr;
    }
}

bool RawTakeReader::open(std::string* error) {
    if (!make_nats_options(connection_, &options_, error)) return false;
    (void)natsOptions_SetMaxReconnect(options_, 10);
    (void)natsOptions_SetReconnectWait(options_, 250);
    if (!nats_ok(natsConnection_Connect(&nc_, options_), ("connect to " + connection_.nats_url).c_str(), error))
        return false;
    jsOptions jo;
    jsOptions_Init(&jo);
    jo.Wait = query_.message_wait_ms;
    if (!nats_ok(natsConnection_JetStream(&js_, nc_, &jo), "JetStream context", error)) return false;

    natsMsg* last = nullptr;
    jsErrCode code{};
    const natsStatus s = js_GetLastMsg(&last, js_, kRawStreamName, subject_.c_str(), nullptr, &code);
    if (s == NATS_NOT_FOUND) {
        *error = std::string("no raw samples on ") + subject_ + " in JetStream stream " + kRawStreamName;
        return false;
    }
    if (!nats_ok(s, (std::string("last message of ") + subject_ + " in " + kRawStreamName).c_str(), error))
        return false;
    last_seq_ = natsMsg_GetSequence(last);
    const std::int64_t last_us = natsMsg_GetTime(last) / 1000;
    natsMsg_Destroy(last);
    if (query_.from_us != std::numeric_limits<std::int64_t>::min() && last_us < query_.from_us - kTakeClockMarginUs) {
        done_ = true;  // everything of this subject was stored before the range starts
        return true;
    }

    jsSubOptions so;
    jsSubOptions_Init(&so);
    so.Stream = kRawStreamName;
    so.Ordered = true;
    if (query_.from_us == std::numeric_limits<std::int64_t>::min()) {
        so.Config.DeliverPolicy = js_DeliverAll;
    } else {
        so.Config.DeliverPolicy = js_DeliverByStartTime;
        so.Config.OptStartTime = (query_.from_us - kTakeClockMarginUs) * 1000;
    }
    return nats_ok(js_SubscribeSync(&sub_, js_, subject_.c_str(), &jo, &so, &code),
                   ("ordered consumer on " + subject_).c_str(), error);
}

int RawTakeReader::next(SegmentSample& out, std::string* error) {
    for (;;) {
        if (have_records_) {
            const int r = records_.next(out, error);
            if (r != 0) {
                if (r < 0) *error = subject_ + ": message " + std::to_string(messages_) + ": " + *error;
                return r;
            }
            if (records_.truncated()) {
                // A file may end in a cut record (a crash); a stored message is whole or absent.
                *error = subject_ + ": message " + std::to_string(messages_) + ": " + records_.truncation();
                return -1;
            }
            have_records_ = false;
        }
        if (done_ || sub_ == nullptr) return 0;
        natsMsg* m = nullptr;
        const natsStatus s = natsSubscription_NextMsg(&m, sub_, query_.message_wait_ms);
        if (s != NATS_OK) {
            *error = subject_ + ": no message within " + std::to_string(query_.message_wait_ms) + " ms after " +
                     std::to_string(messages_) + " (" + natsStatus_GetText(s) + ")";
            return -1;
        }
        jsMsgMetaData* meta = nullptr;
        if (natsMsg_GetMetaData(&meta, m) != NATS_OK || natsMsg_GetDataLength(m) == 0) {
            natsMsg_Destroy(m);  // not a stream message (nothing the library passes on today)
            continue;
        }
        const std::uint64_t seq = meta->Sequence.Stream;
        const std::int64_t stored_us = meta->Timestamp / 1000;
        jsMsgMetaData_Destroy(meta);
        if (seq >= last_seq_) done_ = true;
        if (query_.to_us != std::numeric_limits<std::int64_t>::max() && stored_us > query_.to_us + kTakeClockMarginUs) {
            done_ = true;  // stored after the range ends: samples of later
            natsMsg_Destroy(m);
            continue;
        }
        ++messages_;
        std::string records(natsMsg_GetData(m), static_cast<std::size_t>(natsMsg_GetDataLength(m)));
        natsMsg_Destroy(m);
        if (!records_.open_records(std::move(records), error)) return -1;
        have_records_ = true;
    }
}

}  // namespace mocap::cluster
