/*
 * mocap_wire.h — the whole wire library in one include (docs/protocol.md is the prose).
 */
#ifndef MOCAP_WIRE_MOCAP_WIRE_H
#define MOCAP_WIRE_MOCAP_WIRE_H

#include "mocap_wire/mw_busload.h"
#include "mocap_wire/mw_can.h"
#include "mocap_wire/mw_common.h"
#include "mocap_wire/mw_crc32.h"
#include "mocap_wire/mw_keepalive.h"
#include "mocap_wire/mw_packet.h"
#include "mocap_wire/mw_scale.h"

#endif /* MOCAP_WIRE_MOCAP_WIRE_H */
