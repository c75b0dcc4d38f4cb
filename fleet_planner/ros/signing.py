"""Signatures on the wire (issue 9, deliverable 5): the ROS side of :mod:`fleet_planner.auth`.

:class:`Keys` is what a node was configured with (its signing key file, the file of keys it
accepts); it signs and checks records on a topic (the channel is the fully qualified topic name).
A ``nav_msgs/Path`` has no field for a signature: a timed path is signed by a
:class:`~msg_schemas.records.PathAuth` record on ``/robots/<id>/timed_path_auth`` that carries
the path's digest (:func:`path_digest`: SHA-256 over its header stamp and frame, and every pose's
stamp, position and orientation, little-endian); :class:`PathPairing` holds whichever of the two
comes first until its partner arrives.
"""
from __future__ import annotations

import hashlib
import struct
from dataclasses import replace
from typing import TypeVar

from nav_msgs.msg import Path

from fleet_planner.auth import WINDOW_S, Signer, Verifier
from msg_schemas.convert import stamp_to_ns
from msg_schemas.records import PathAuth, Record, unsigned_json

R = TypeVar("R", bound=Record)


def path_digest(msg: Path) -> str:
    """The SHA-256 (hex) of a path's content: what its PathAuth vouches for."""
    h = hashlib.sha256()
    frame = msg.header.frame_id.encode("utf-8", "surrogatepass")
    h.update(struct.pack("<qI", stamp_to_ns(msg.header.stamp), len(frame)) + frame)
    for p in msg.poses:
        o, q = p.pose.position, p.pose.orientation
        h.update(struct.pack("<q7d", stamp_to_ns(p.header.stamp), o.x, o.y, o.z, q.x, q.y, q.z, q.w))
    return h.hexdigest()


class Keys:
    """A node's keys: ``sign_file`` (its own key, the first line; empty: it signs nothing) and
    ``trust_file`` (the keys it accepts; empty: it checks nothing)."""

    def __init__(self, sign_file: str = "", trust_file: str = "", window_s: float = WINDOW_S):
        self.signer = Signer.from_file(sign_file) if sign_file else None
        self.verifier = Verifier.from_file(trust_file, window_s) if trust_file else None

    @property
    def checks(self) -> bool:
        return self.verifier is not None

    def sign(self, rec: R, channel: str) -> R:
        """``rec`` with its signature for ``channel`` (unchanged without a signing key)."""
        if self.signer is None:
            return rec
        return replace(rec, auth=self.signer.sign(channel, unsigned_json(rec)))  # type: ignore[call-arg]

    def problem(self, rec: Record, channel: str) -> str | None:
        """Why ``rec`` on ``channel`` is not to be believed (None: it is, or nothing is checked)."""
        if self.verifier is None:
            return None
        return self.verifier.problem(channel, unsigned_json(rec), getattr(rec, "auth", None))

    def path_auth(self, msg: Path, robot_id: str, channel: str) -> PathAuth | None:
        """The signed PathAuth of ``msg`` for ``channel`` (the auth topic), None without a key."""
        if self.signer is None:
            return None
        return self.sign(PathAuth(robot_id=robot_id, path_id=stamp_to_ns(msg.header.stamp),
                                  digest=path_digest(msg)), channel)

    @property
    def refused(self) -> int:
        return self.verifier.total_refused if self.verifier is not None else 0


class PathPairing:
    """Pairs timed paths with their PathAuth records (the latest of each is kept). ``offer_*``
    return the path to follow once a pair checks out, else None; a refusal is in ``problem``."""

    def __init__(self, keys: Keys, robot_id: str, channel: str):
        self.keys, self.robot_id, self.channel = keys, robot_id, channel
        self.path: Path | None = None
        self.auth: PathAuth | None = None
        self.problem: str | None = None

    def offer_path(self, msg: Path) -> Path | None:
        if self.path is not None and self.keys.verifier is not None:  # the last one never had a good signature
            self.keys.verifier.refused["unsigned"] = self.keys.verifier.refused.get("unsigned", 0) + 1
        self.path = msg
        return self._pair()

    def offer_auth(self, rec: PathAuth) -> Path | None:
        self.problem = None
        if rec.robot_id != self.robot_id:
            self.problem = f"path_auth.robot_id: for {rec.robot_id!r}, not this robot"
            return None
        why = self.keys.problem(rec, self.channel)
        if why:
            self.problem = f"path_auth.auth: {why}"
            return None
        self.auth = rec
        return self._pair()

    def _pair(self) -> Path | None:
        path, auth = self.path, self.auth
        if path is None or auth is None or auth.path_id != stamp_to_ns(path.header.stamp):
            return None
        self.path = self.auth = None
        if auth.digest != path_digest(path):
            self.problem = "timed path: does not match its signed digest"
            return None
        return path


__all__ = ["Keys", "PathPairing", "path_digest"]
