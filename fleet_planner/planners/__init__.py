"""Planner registry: ``get_planner("md")`` etc. Every planner implements :class:`Planner`."""
from __future__ import annotations

from importlib import import_module

from .base import Planner, Progress

#: name -> "module:Class", imported on first use so a planner's dependencies load only when asked for
_REGISTRY = {
    "md": "fleet_planner.planners.md:MDPlanner",
    "md-box": "fleet_planner.planners.md:MDPlanner",   # MDPlanner(mode="box"), see _PRESETS
    "prior": "fleet_planner.planners.prior:PriorPlanner",
}

#: registered variants: the options their name fixes
_PRESETS: dict[str, dict] = {"md-box": {"mode": "box"}}


def planner_names() -> list[str]:
    return list(_REGISTRY)


def get_planner(name: str, **options) -> Planner:
    try:
        target = _REGISTRY[name]
    except KeyError:
        raise ValueError(f"planner: unknown planner {name!r}; choose one of {', '.join(_REGISTRY)}") from None
    module, cls = target.split(":")
    return getattr(import_module(module), cls)(**_PRESETS.get(name, {}), **options)


__all__ = ["Planner", "Progress", "get_planner", "planner_names"]
