"""A Foxglove WebSocket client written here from the protocol (foxglove/ws-protocol's spec), on
the ``websockets`` package, so that a test sees what the Foxglove app sees: JSON ``serverInfo``
and ``advertise`` (channels: id, topic, encoding, schemaName, schema), a JSON ``subscribe``,
then binary ``messageData`` frames (opcode 1, uint32 subscription id, uint64 log time [ns],
the message bytes). foxglove-sdk's servers speak it under the subprotocol ``foxglove.sdk.v1``
(the same protocol as ``foxglove.websocket.v1``, renamed), which is offered first."""

from __future__ import annotations

import contextlib
import json
import struct
from collections.abc import Iterator
from types import TracebackType
from typing import Any

SUBPROTOCOLS = ("foxglove.sdk.v1", "foxglove.websocket.v1")
MESSAGE_DATA = 0x01
TIMEOUT_S = 300.0
"""A hang guard only: how long a receive may wait before the test fails."""


class FoxgloveClient:
    """One connection: ``channels()`` the advertised ones, ``subscribe`` some, iterate
    ``messages()`` as (channel, log time [ns], message bytes)."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.advertised: dict[int, dict[str, Any]] = {}
        self._subscriptions: dict[int, int] = {}  # subscription id -> channel id

    def __enter__(self) -> FoxgloveClient:
        from websockets.sync.client import connect

        self._stack = contextlib.ExitStack()
        self.ws = self._stack.enter_context(connect(
            self.url, subprotocols=list(SUBPROTOCOLS), proxy=None, max_size=None,
            open_timeout=TIMEOUT_S))
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self._stack.close()

    def channels(self) -> dict[int, dict[str, Any]]:
        """Read the server's JSON messages up to its first ``advertise``: channel id ->
        its advertisement."""
        while not self.advertised:
            op = json.loads(self.ws.recv(timeout=TIMEOUT_S))
            if op["op"] == "advertise":
                self.advertised = {int(c["id"]): c for c in op["channels"]}
        return self.advertised

    def subscribe(self, channel_ids: list[int]) -> None:
        """Subscribe to the channels, all in one ``subscribe`` message."""
        subs = [{"id": k, "channelId": c} for k, c in enumerate(channel_ids)]
        self._subscriptions = {s["id"]: s["channelId"] for s in subs}
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    def messages(self) -> Iterator[tuple[dict[str, Any], int, bytes]]:
        """(advertised channel, log time [ns], message bytes) of every ``messageData``."""
        while True:
            frame = self.ws.recv(timeout=TIMEOUT_S)
            if isinstance(frame, str) or frame[0] != MESSAGE_DATA:
                continue  # status and other operations
            sub, log_time = struct.unpack_from("<IQ", frame, 1)
            yield self.advertised[self._subscriptions[sub]], log_time, bytes(frame[13:])
