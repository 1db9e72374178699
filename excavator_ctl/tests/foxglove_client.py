"""A Foxglove WebSocket client (protocol foxglove.sdk.v1) for the live-view test.

Connects to ws://HOST:PORT, subscribes to the live view's topics, and decodes what arrives for up to
SECONDS (with a third argument `hold`, stays the whole time instead of leaving once every topic
has arrived): protobuf channels with Foxglove's published schema classes (foxglove-schemas-protobuf), JSON
channels with json. Prints one JSON object: per topic the advertised schema and the count of messages
decoded, and a few decoded values. Exits non-zero on a message that does not decode.
"""
import base64
import json
import struct
import sys
import time

from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.Grid_pb2 import Grid
from foxglove_schemas_protobuf.Log_pb2 import Log
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

PROTOBUF = {
    "foxglove.FrameTransforms": FrameTransforms,
    "foxglove.Grid": Grid,
    "foxglove.Log": Log,
    "foxglove.SceneUpdate": SceneUpdate,
}
TOPICS = ["/tf", "/terrain", "/signals", "/scene", "/log"]


def main():
    url, seconds = sys.argv[1], float(sys.argv[2])
    hold = len(sys.argv) > 3 and sys.argv[3] == "hold"
    out = {"topics": {}, "frames": [], "grid": None, "signals": None, "logs": []}
    channels = {}
    subs = {}
    with connect(url, subprotocols=["foxglove.sdk.v1"], open_timeout=10, max_size=None) as ws:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            try:
                raw = ws.recv(timeout=max(0.05, deadline - time.monotonic()))
            except (TimeoutError, ConnectionClosed):
                # The session is over (the server closed) or the time is up.
                break
            if isinstance(raw, str):
                msg = json.loads(raw)
                if msg.get("op") == "advertise":
                    new = []
                    for ch in msg["channels"]:
                        if ch["topic"] in TOPICS and ch["id"] not in channels:
                            channels[ch["id"]] = ch
                            sub_id = len(subs) + 1
                            subs[sub_id] = ch
                            new.append({"id": sub_id, "channelId": ch["id"]})
                            out["topics"][ch["topic"]] = {
                                "schemaName": ch["schemaName"],
                                "encoding": ch["encoding"],
                                "count": 0,
                            }
                    if new:
                        ws.send(json.dumps({"op": "subscribe", "subscriptions": new}))
                continue
            if raw[0] != 1:  # MessageData
                continue
            sub_id, _log_time = struct.unpack_from("<IQ", raw, 1)
            payload = raw[13:]
            ch = subs[sub_id]
            topic = ch["topic"]
            if ch["encoding"] == "protobuf":
                # The advertised schema is a base64 FileDescriptorSet of the well-known type.
                base64.b64decode(ch["schema"], validate=True)
                m = PROTOBUF[ch["schemaName"]]()
                m.ParseFromString(payload)
                if topic == "/tf" and not out["frames"]:
                    out["frames"] = [t.child_frame_id for t in m.transforms]
                if topic == "/terrain" and out["grid"] is None:
                    known = sum(
                        1
                        for (v,) in struct.iter_unpack("<f", m.data)
                        if v == v  # not NaN
                    )
                    out["grid"] = {
                        "columns": m.column_count,
                        "cells": len(m.data) // 4,
                        "known": known,
                        "frame_id": m.frame_id,
                    }
                if topic == "/log":
                    out["logs"].append(m.message)
            else:
                json.loads(ch["schema"])
                value = json.loads(payload)
                if value.get("pressure_pa", {}).get("boom_head") is not None:
                    out["signals"] = value
            out["topics"][topic]["count"] += 1
            counts = out["topics"]
            if not hold and all(counts.get(t, {}).get("count", 0) >= 1 for t in TOPICS) and counts["/tf"]["count"] >= 50 \
                    and out["signals"] is not None:
                break
    print(json.dumps(out))


if __name__ == "__main__":
    main()
