"""Only the latest status per robot is processed: :class:`StatusInbox`.

A robot's status is its state, not an event: of the statuses of one robot that arrive between two
planning steps only the last one matters (a pick or place lasts seconds, far longer than a step,
so its mode is still seen). The planner node files each raw status here on arrival (a cheap look
at its ``id``, no parse) and parses only the latest of each robot before it steps; at 10 Hz and
two steps a second that is one parse in five. A status whose id cannot be made out is handed back
at once for the full parse (and its rejection); so are all statuses once :data:`MAX_PENDING`
robots wait, so that forged ids cannot grow the inbox.
"""
from __future__ import annotations

import re

from msg_schemas.records import MAX_NAME_CHARS

#: the most robots whose statuses wait in the inbox
MAX_PENDING = 20_000
#: a status longer than this is parsed at once (statuses are a few hundred bytes)
MAX_PENDING_CHARS = 4096
_ID = re.compile(r'"id"\s*:\s*"([A-Za-z0-9_]{1,' + str(MAX_NAME_CHARS) + r'})"')


class StatusInbox:
    """Raw statuses by robot id, the latest one each, with when it arrived."""

    def __init__(self) -> None:
        self._latest: dict[str, tuple[str, float]] = {}
        self.offered = 0
        self.superseded = 0

    def __len__(self) -> int:
        return len(self._latest)

    def offer(self, raw: str, now: float) -> tuple[str, float] | None:
        """File ``raw`` (arrived at ``now``); returns it back when it must be handled at once (no
        plain id in it, too long, or the inbox full), else None. The id is only a key here: the
        full parse later decides whether the status is valid."""
        self.offered += 1
        m = _ID.search(raw, 0, MAX_PENDING_CHARS) if len(raw) <= MAX_PENDING_CHARS else None
        if m is None or len(raw) > MAX_PENDING_CHARS:
            return raw, now
        key = m.group(1)
        if key in self._latest:
            self.superseded += 1
        elif len(self._latest) >= MAX_PENDING:
            return raw, now
        self._latest[key] = (raw, now)
        return None

    def take(self) -> list[tuple[str, float]]:
        """Every waiting status (the latest of each robot) in arrival order of the robots; the inbox
        is empty after."""
        out = list(self._latest.values())
        self._latest = {}
        return out


__all__ = ["MAX_PENDING", "StatusInbox"]
