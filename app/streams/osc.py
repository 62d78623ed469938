"""One UDP destination for OSC bundles, shared by the VMC and VRChat sinks.

A receiver that is not running must not slow or stop the reconstruction: sends are
non-blocking, and a failed send (nobody listening, a full socket buffer, a network
that went away) is counted, not raised; the sink's summary shows the count.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder
from pythonosc.udp_client import UDPClient


def message(address: str, args: Sequence[Any]) -> Any:
    """An OSC message; Python floats go out as 32-bit floats, ints as int32, str as string
    (the types VMC and VRChat read)."""
    b = OscMessageBuilder(address=address)
    for a in args:
        b.add_arg(a)
    return b.build()


class OscTarget:
    """host:port, resolved once (a name lookup per frame would stall the inference thread)."""

    def __init__(self, host: str, port: int) -> None:
        if not 0 < int(port) < 65536:
            raise ValueError(f"port {port} is not a UDP port")
        self.host, self.port = host, int(port)
        try:
            self._client = UDPClient(host, self.port)
        except OSError as e:  # an unknown host name: say which, not just the resolver's errno
            raise OSError(f"stream host {host!r}: {e.strerror or e}") from e
        self.sent = 0
        self.errors = 0
        self.last_error: str | None = None

    def send_bundle(self, messages: Iterable[Any]) -> None:
        """All of one frame's messages as one bundle (receivers apply a frame at once)."""
        b = OscBundleBuilder(IMMEDIATELY)
        for m in messages:
            b.add_content(m)
        try:
            self._client.send(b.build())
            self.sent += 1
        except OSError as e:
            self.errors += 1
            self.last_error = f"{type(e).__name__}: {e}"

    def close(self) -> None:
        self._client.close()

    def summary(self) -> dict[str, Any]:
        return {"target": f"{self.host}:{self.port}", "bundles": self.sent, "errors": self.errors,
                **({"last_error": self.last_error} if self.last_error else {})}
