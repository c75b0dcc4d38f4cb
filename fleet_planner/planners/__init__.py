"""The planner registry: every named planner variant, registered once.

``get_planner("md")``, ``get_planner("md-box", margin=0.05)``: a variant is a planner class and the
options that make it that variant (``"md-box"`` is :class:`~fleet_planner.planners.md.MDPlanner`
with ``mode="box"``, the collision boxes of You & Ji, "Design of a Multi-robot Bin Packing System
in an Automatic Warehouse"); the caller's options are added to them. The CLI, the fleet manager,
the delivery simulation, the benchmarks and the tests build their planners here. Every planner
implements :class:`Planner`.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import import_module
from types import MappingProxyType
from typing import Any

from .base import Planner, Progress


@dataclass(frozen=True)
class Variant:
    """A named planner: its class as ``"module:Class"`` (imported on first use, so that a planner's
    dependencies load only when it is asked for) and the options that make this variant."""

    target: str
    options: Mapping[str, Any] = field(default_factory=dict)
    summary: str = ""

    def planner_class(self) -> type[Planner]:
        module, cls = self.target.split(":")
        return getattr(import_module(module), cls)


_REGISTRY: dict[str, Variant] = {}


def register(name: str, target: str, summary: str = "", **options: Any) -> None:
    """Register the planner variant ``name``: the class ``target`` ("module:Class") with ``options``."""
    if name in _REGISTRY:
        raise ValueError(f"planner: {name!r} is registered already")
    _REGISTRY[name] = Variant(target, MappingProxyType(dict(options)), summary)


register("md", "fleet_planner.planners.md:MDPlanner",
         "md v2: the (M,D) network of You & Ji with exact collision regions, holds anywhere, route choice "
         "and priority search; crowded instances and worse plans to the dense solver (--holds none: the paper's "
         "departure delays)")
register("md-box", "fleet_planner.planners.md:MDPlanner",
         "the (M,D) network of You & Ji with the paper's collision boxes", mode="box", holds="none",
         search=False, fallback=None)
register("prior", "fleet_planner.planners.prior:PriorPlanner",
         "prioritized planning in space-time (van den Berg & Overmars)")
register("md-departure", "fleet_planner.planners.md:MDPlanner",
         "the paper's method: exact collision regions, departure delays only, greedy re-ordering (md before v2)",
         mode="exact", holds="none", search=False, fallback=None)
register("md-holds", "fleet_planner.planners.md:MDPlanner",
         "md with holds anywhere along the path but no route choice "
         "(earliest arrival against the higher robots' timed trajectories)",
         mode="exact", holds="anywhere", detours=0, crowded=False, compare_above=None, improve=0)
register("md-routes", "fleet_planner.planners.md:MDPlanner",
         "md with route choice in time: robots that wait long try detours, the earliest arrival wins",
         mode="exact", holds="anywhere", detours=2, crowded=False, compare_above=None, improve=0)
register("crowd", "fleet_planner.planners.crowd:CrowdPlanner", "LaCAM/PIBT for dense crowds, timed by precedence")
register("dense", "fleet_planner.planners.crowd:DensePlanner", "the dense-crowd solver (LaCAM/PIBT + LNS; = crowd)")


def planner_names() -> list[str]:
    """The registered variants, in registration order."""
    return list(_REGISTRY)


def planner_summary(name: str) -> str:
    """One line on what the variant ``name`` is (for help texts)."""
    return _REGISTRY[name].summary


def get_planner(name: str, **options: Any) -> Planner:
    """A new planner of the variant ``name`` with its options and ``options`` (which may add to
    them, not contradict them: ``get_planner("md-box", mode="exact")`` is a ValueError)."""
    try:
        variant = _REGISTRY[name]
    except KeyError:
        raise ValueError(f"planner: unknown planner {name!r}; choose one of {', '.join(_REGISTRY)}") from None
    for key, value in options.items():
        if key in variant.options and variant.options[key] != value:
            raise ValueError(f"planner {name!r}: {key} is {variant.options[key]!r} in this variant "
                             f"(got {key}={value!r})")
    return variant.planner_class()(**{**variant.options, **options})


__all__ = ["Planner", "Progress", "Variant", "get_planner", "planner_names", "planner_summary", "register"]
