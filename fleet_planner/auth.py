"""Shared-key signatures on the fleet's commands (issue 9, deliverable 5): pure, stdlib only
(``hmac`` with SHA-256), no rclpy.

Where keys are configured, the planner signs what it tells the robots and the clients (task events,
timed paths) and checks what clients tell it (tasks); agents and ``fleet-submit`` check what the
planner says. A signature is the ``auth`` member of a record, ``{"key": id, "ctr": n, "mac": hex}``:

* ``mac`` = HMAC-SHA256(secret of ``key``, ``channel`` NUL ``ctr`` NUL ``body``), where ``channel``
  is the fully qualified topic (a record signed for one topic or robot is no good on another) and
  ``body`` the record's canonical JSON without ``auth`` (``Record.to_json()``, see
  msg_schemas/records.py; a timed path is signed through its digest, fleet_planner/ros/signing.py);
* ``ctr`` is the signer's counter: nanoseconds of its wall clock, and always more than its last one,
  so it grows across restarts. A verifier takes a counter only if it is larger than the last one it
  took from that key on that channel (no replays) and within ``window_s`` of its own wall clock
  (an old message recorded and replayed after the verifier restarted is refused too); the hosts'
  clocks must agree to within the window (NTP).

Key files (the operator makes them; readable by the node's user only): one key per line,
``<key id> <secret in hex, at least 32 bytes>``; ``#`` starts a comment. A signer uses the first key
of its file; a verifier accepts any key of its file. Give the planner's key to the planner, the
agents and the clients that follow events; the client keys to the clients and the planner. HMAC keys
are symmetric: whoever can check a key can sign with it, so a client that holds the planner's key
could speak as the planner; keep one key per trust domain and rotate by key id.
"""
from __future__ import annotations

import hashlib
import hmac
import os
import re
import stat
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

#: the shortest secret taken (bytes): as long as the SHA-256 output
MIN_SECRET_BYTES = 32
#: how far (s) a counter may be from the verifier's wall clock, either way
WINDOW_S = 300.0
#: the most (key, channel) pairs whose last counter a verifier remembers
MAX_CHANNELS = 100_000

_KEY_ID = re.compile(r"[A-Za-z0-9_.\-]{1,64}")
_HEX = re.compile(r"[0-9a-fA-F]+")


class AuthError(ValueError):
    """A key file that cannot be used (names the file and the line)."""


def load_keys(path: str | Path) -> dict[str, bytes]:
    """The keys of a key file, by id, in file order; :class:`AuthError` naming the line at fault.
    A file that others than its owner may read is refused (a shared secret must stay secret)."""
    path = Path(path)
    try:
        mode = path.stat().st_mode
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise AuthError(f"{path}: cannot read the key file ({exc})") from None
    if mode & (stat.S_IRWXG | stat.S_IRWXO) and os.name == "posix":
        raise AuthError(f"{path}: group or others may read it (chmod 600 {path})")
    keys: dict[str, bytes] = {}
    for n, line in enumerate(text.splitlines(), 1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        parts = line.split()
        if len(parts) != 2:
            raise AuthError(f"{path}:{n}: expected '<key id> <secret in hex>'")
        key_id, secret = parts
        if not _KEY_ID.fullmatch(key_id):
            raise AuthError(f"{path}:{n}: key id must be 1-64 letters, digits, '_', '.', '-'")
        if not _HEX.fullmatch(secret) or len(secret) % 2:
            raise AuthError(f"{path}:{n}: key {key_id!r}: the secret must be hex digits")
        if len(secret) < 2 * MIN_SECRET_BYTES:
            raise AuthError(f"{path}:{n}: key {key_id!r}: the secret must have at least {MIN_SECRET_BYTES} bytes")
        if key_id in keys:
            raise AuthError(f"{path}:{n}: key {key_id!r} given twice")
        keys[key_id] = bytes.fromhex(secret)
    if not keys:
        raise AuthError(f"{path}: no key in the file")
    return keys


def new_key_line(key_id: str) -> str:
    """A fresh key file line for ``key_id`` (``python -m fleet_planner.auth ID >> keys``)."""
    return f"{key_id} {os.urandom(MIN_SECRET_BYTES).hex()}"


def _mac(secret: bytes, channel: str, ctr: int, body: str) -> str:
    msg = b"\0".join((channel.encode("utf-8", "surrogatepass"), str(ctr).encode(),
                      body.encode("utf-8", "surrogatepass")))
    return hmac.new(secret, msg, hashlib.sha256).hexdigest()


class Signer:
    """Signs with one key (by default the first of a key file)."""

    def __init__(self, key_id: str, secret: bytes, clock: Callable[[], int] = time.time_ns):
        self.key_id, self._secret, self._clock = key_id, secret, clock
        self._last = 0

    @classmethod
    def from_file(cls, path: str | Path) -> Signer:
        key_id, secret = next(iter(load_keys(path).items()))
        return cls(key_id, secret)

    def sign(self, channel: str, body: str) -> dict[str, Any]:
        """The ``auth`` member for ``body`` on ``channel``."""
        self._last = max(self._last + 1, self._clock())
        return {"key": self.key_id, "ctr": self._last, "mac": _mac(self._secret, channel, self._last, body)}


@dataclass
class Verifier:
    """Checks signatures against ``keys`` (id -> secret); counts what it refuses, by reason."""

    keys: Mapping[str, bytes]
    window_s: float = WINDOW_S
    clock: Callable[[], int] = time.time_ns
    refused: dict[str, int] = field(default_factory=dict)
    _last: dict[tuple[str, str], int] = field(default_factory=dict)

    @classmethod
    def from_file(cls, path: str | Path, window_s: float = WINDOW_S) -> Verifier:
        return cls(load_keys(path), window_s)

    @property
    def total_refused(self) -> int:
        return sum(self.refused.values())

    def problem(self, channel: str, body: str, auth: Mapping[str, Any] | None) -> str | None:
        """None if ``auth`` is a good, fresh signature of ``body`` on ``channel`` (and then its
        counter is taken), else why not in a few words (counted)."""
        why, reason = self._check(channel, body, auth)
        if why is not None:
            self.refused[reason] = self.refused.get(reason, 0) + 1
        return why

    def _check(self, channel: str, body: str, auth: Mapping[str, Any] | None) -> tuple[str | None, str]:
        if auth is None:
            return "unsigned (keys are configured: every record must be signed)", "unsigned"
        key_id, ctr, mac = auth.get("key"), auth.get("ctr"), auth.get("mac")
        secret = self.keys.get(key_id) if isinstance(key_id, str) else None
        if secret is None or not isinstance(key_id, str):
            return "signed with a key this node does not accept", "unknown key"
        if not isinstance(ctr, int) or isinstance(ctr, bool) or not isinstance(mac, str):
            return "malformed signature", "malformed"
        if not hmac.compare_digest(_mac(secret, channel, ctr, body), mac):
            return "wrong signature", "bad signature"
        now = self.clock()
        if abs(ctr - now) > self.window_s * 1e9:
            return f"signed {(now - ctr) / 1e9:.3g} s from this node's clock (at most {self.window_s:g} s)", "stale"
        last = self._last.get((key_id, channel))
        if last is not None and ctr <= last:
            return "replayed (its counter is not above the last one taken)", "replay"
        if last is None and len(self._last) >= MAX_CHANNELS:
            self._last.pop(next(iter(self._last)))
        self._last[(key_id, channel)] = ctr
        return None, ""


def main(argv: list[str] | None = None) -> None:
    """``python -m fleet_planner.auth KEY_ID``: print a fresh key file line."""
    import sys

    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1 or not _KEY_ID.fullmatch(args[0]):
        sys.exit("usage: python -m fleet_planner.auth KEY_ID   (prints '<key id> <secret>' for a key file)")
    print(new_key_line(args[0]))


if __name__ == "__main__":
    main()


__all__ = ["MAX_CHANNELS", "MIN_SECRET_BYTES", "WINDOW_S", "AuthError", "Signer", "Verifier", "load_keys",
           "new_key_line"]
