"""A Foxglove WebSocket client for tests/tests/stack/foxglove_ws.rs.

Connects to argv[1] offering foxglove.websocket.v1, subscribes to every
advertised channel and decodes every message it receives with the channel's
own schema: CDR through mcap-ros2-support from the `ros2msg` text, JSON
validated by jsonschema; then joins again as a late viewer. Also plays the
misbehaving viewer: a client without
the subprotocol, a request that is not JSON, a subscription to a channel
that does not exist, an oversized message. Stops once every topic in argv[2]
(comma-separated) has at least one message from the running stack and the
latched ones came on subscription, or after argv[3] seconds. Prints a JSON
summary on stdout.
"""

import json
import struct
import sys
import time

import jsonschema
from mcap.records import Schema
from mcap_ros2.decoder import DecoderFactory
from websockets.exceptions import ConnectionClosed, InvalidStatus
from websockets.sync.client import connect

URL, REQUIRED, DEADLINE_S = sys.argv[1], sys.argv[2].split(","), float(sys.argv[3])
SUB = "foxglove.websocket.v1"
summary = {"counts": {}, "statuses": [], "errors": []}


def fail(msg):
    summary["errors"].append(msg)


# Without the subprotocol: refused at the handshake.
try:
    with connect(URL, open_timeout=10) as ws:
        fail("a client without the subprotocol was accepted")
except InvalidStatus as e:
    summary["refused_status"] = e.response.status_code

factory = DecoderFactory()
start = time.monotonic()
with connect(URL, subprotocols=[SUB], open_timeout=10, max_size=None, ping_interval=None) as ws:
    summary["subprotocol"] = ws.subprotocol
    info = json.loads(ws.recv(timeout=10))
    summary["server_op"] = info.get("op")
    adv = json.loads(ws.recv(timeout=10))
    assert adv["op"] == "advertise", adv
    channels = {c["id"]: c for c in adv["channels"]}
    summary["topics"] = sorted(c["topic"] for c in channels.values())

    # Hostile requests first: each answered by a status, the session goes on.
    ws.send("{not json")
    ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 900, "channelId": 4242}]}))
    ws.send(json.dumps({"op": "getParameters", "parameterNames": []}))

    subs = {}
    for i, (cid, c) in enumerate(sorted(channels.items())):
        subs[i] = c
    ws.send(json.dumps({"op": "subscribe",
                        "subscriptions": [{"id": i, "channelId": c["id"]} for i, c in subs.items()]}))
    # The same subscription id twice is refused.
    ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 0, "channelId": 1}]}))

    decoders = {}
    first_times = {}
    while time.monotonic() - start < DEADLINE_S:
        try:
            m = ws.recv(timeout=1)
        except TimeoutError:
            continue
        if isinstance(m, str):
            v = json.loads(m)
            if v.get("op") == "status":
                summary["statuses"].append(v)
            continue
        op, sub, t = struct.unpack_from("<BIQ", m)
        payload = m[13:]
        if op != 1 or sub not in subs:
            fail(f"frame with opcode {op}, subscription {sub}")
            continue
        c = subs[sub]
        topic = c["topic"]
        try:
            if c["encoding"] == "cdr":
                key = c["id"]
                if key not in decoders:
                    schema = Schema(id=c["id"], name=c["schemaName"], encoding=c["schemaEncoding"],
                                    data=c["schema"].encode())
                    decoders[key] = factory.decoder_for("cdr", schema)
                decoders[key](payload)
            elif c["encoding"] == "json" and c["schemaEncoding"] == "jsonschema":
                key = c["id"]
                if key not in decoders:
                    schema = json.loads(c["schema"])
                    jsonschema.validators.validator_for(schema).check_schema(schema)
                    decoders[key] = jsonschema.validators.validator_for(schema)(schema).validate
                decoders[key](json.loads(payload))
            else:
                fail(f"{topic}: no decoder for {c['encoding']}")
        except Exception as e:  # noqa: BLE001 - reported, not raised
            fail(f"{topic}: {e!r}")
        summary["counts"][topic] = summary["counts"].get(topic, 0) + 1
        first_times.setdefault(topic, time.monotonic() - start)
        if all(summary["counts"].get(r, 0) >= 2 for r in REQUIRED):
            break

    # Unsubscribe from the 1 kHz sensor channel: nothing more of it after
    # the server has taken the request (a status answers an unknown id,
    # which marks that point).
    sensor = next(i for i, c in subs.items() if c["topic"] == "/controller/sensor")
    ws.send(json.dumps({"op": "unsubscribe", "subscriptionIds": [sensor]}))
    ws.send(json.dumps({"op": "unsubscribe", "subscriptionIds": [7777]}))
    marked = False
    after = 0
    others = 0
    t0 = time.monotonic()
    while time.monotonic() - t0 < 10 and others < 50:
        try:
            m = ws.recv(timeout=1)
        except TimeoutError:
            continue
        if isinstance(m, str):
            v = json.loads(m)
            if "7777" in v.get("message", ""):
                marked = True
            summary["statuses"].append(v)
            continue
        _, sub, _ = struct.unpack_from("<BIQ", m)
        if marked:
            if sub == sensor:
                after += 1
            else:
                others += 1
    summary["sensor_after_unsubscribe"] = after
    summary["others_after_unsubscribe"] = others
    summary["first_seconds"] = first_times

# A viewer that joins mid-episode: the episode's configuration, scene (the
# arm among it) and events come first, before anything newer.
with connect(URL, subprotocols=[SUB], open_timeout=10, max_size=None, ping_interval=None) as late:
    late.recv(timeout=10)
    chans = {c["topic"]: c for c in json.loads(late.recv(timeout=10))["channels"]}
    # The sensor channel in the same request: the node logs it every
    # millisecond, so what comes before its first message was kept for us.
    want = ["/config", "/scene", "/events", "/controller/sensor"]
    late.send(json.dumps({"op": "subscribe", "subscriptions": [
        {"id": i, "channelId": chans[t]["id"]} for i, t in enumerate(want)]}))
    first = []
    while True:
        m = late.recv(timeout=30)
        if isinstance(m, str):
            continue
        _, sub, _ = struct.unpack_from("<BIQ", m)
        if want[sub] == "/controller/sensor":
            break
        first.append((want[sub], m[13:]))
    summary["late_first_topics"] = [t for t, _ in first]
    summary["late_arm"] = any(t == "/scene" and b'"arm/' in p for t, p in first)

# An oversized message ends that client's session only, with close code
# 1009 (message too big): seen while still sending it or after.
with connect(URL, subprotocols=[SUB], open_timeout=10, max_size=None, ping_interval=None) as ws:
    ws.recv(timeout=10)
    ws.recv(timeout=10)
    try:
        ws.send("x" * (1 << 20))
        while True:
            ws.recv(timeout=10)
    except ConnectionClosed as e:
        summary["oversized_close"] = e.rcvd.code if e.rcvd else None
    except TimeoutError:
        fail("an oversized message left the session open")

print(json.dumps(summary))
