"""The fleet demo (``fleet-demo``, ``python -m fleet_planner.ros.demo``) and the fleet bring-up the
system tests share, one module per concern:

* :mod:`.monitor` - :class:`FleetMonitor`, the eyes and hands on the topics; :func:`spin_until`
* :mod:`.bringup` - an in-process fleet on one executor (:func:`bring_up`) or one process per node
  (:func:`start_processes`, :func:`stop_processes`)
* :mod:`.jobs` - random pick-and-place jobs the fleet can do
* :mod:`.summary` - what a run did (:func:`summarise`) and its picture (:func:`plot_run`)
* :mod:`.cli` - the command: options, bring-up, the stream of jobs, the summary (:func:`main`)
"""
from fleet_planner.ros.demo.bringup import Fleet, bring_up, node_command, start_processes, stop_processes
from fleet_planner.ros.demo.cli import main, run_jobs
from fleet_planner.ros.demo.jobs import TERMINAL, random_jobs
from fleet_planner.ros.demo.monitor import FleetMonitor, spin_until
from fleet_planner.ros.demo.summary import Summary, plot_run, summarise

__all__ = ["TERMINAL", "Fleet", "FleetMonitor", "Summary", "bring_up", "main", "node_command", "plot_run",
           "random_jobs", "run_jobs", "spin_until", "start_processes", "stop_processes", "summarise"]
