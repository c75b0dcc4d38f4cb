"""fleet_planner: a central (M,D) collision-model planner for warehouse robot fleets.

The core (this package minus :mod:`fleet_planner.ros`) imports no rclpy.
"""
from .grid import GridMap, MapError, load_scen
from .model import Plan, PlanningError, RobotSpec, TimedPath, timed_path_from_polyline

__all__ = ["GridMap", "MapError", "load_scen", "Plan", "PlanningError", "RobotSpec", "TimedPath",
           "timed_path_from_polyline"]
__version__ = "0.1.0"
