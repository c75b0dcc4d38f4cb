"""The one shape of every node's ``main()`` (that of ROS 2's ``demo_nodes_py``).

Initialise rclpy, build the node, spin it, end quietly on Ctrl-C (``KeyboardInterrupt``) or when
the context is shut down from outside (``ExternalShutdownException``), destroy the node, shut
down; a bad file or parameter (``ValueError``, ``ParameterException``) is said in one line on
stderr, naming the program, with exit status 2::

    def main(args: list[str] | None = None) -> None:
        run_node(PlannerNode, args, prog="planner")
"""
from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TypeVar

import rclpy
from rclpy.context import Context
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

N = TypeVar("N", bound=Node)

#: what a bad configuration raises while a node is built (a file, a parameter, a value out of range)
CONFIG_ERRORS: tuple[type[Exception], ...] = (ValueError, ParameterException)


@contextmanager
def ros_session(args: list[str] | None, *, prog: str, context: Context | None = None,
                errors: tuple[type[Exception], ...] = CONFIG_ERRORS, interrupted: int = 0) -> Iterator[None]:
    """rclpy initialised (in ``context``, else the default one) for the body, shut down after it.

    A ``KeyboardInterrupt`` or ``ExternalShutdownException`` in the body ends it quietly (exit
    status ``interrupted`` if not 0); one of ``errors`` is printed as ``prog: message`` and exits 2.
    """
    rclpy.init(args=args, context=context)
    status = 0
    try:
        yield
    except (KeyboardInterrupt, ExternalShutdownException):
        status = interrupted
    except errors as exc:  # a bad file or parameter: say which, and why
        print(f"{prog}: {exc}", file=sys.stderr)
        status = 2
    finally:
        rclpy.try_shutdown(context=context)
    if status:
        sys.exit(status)


def spin_node(node: Node) -> None:
    """The default way to run a node: :func:`rclpy.spin` until shutdown."""
    rclpy.spin(node)


def run_node(make_node: Callable[[], N], args: list[str] | None = None, *, prog: str,
             spin: Callable[[N], int | None] = spin_node, errors: tuple[type[Exception], ...] = CONFIG_ERRORS,
             interrupted: int = 0) -> None:
    """``main()`` of a node: init, ``node = make_node()``, ``spin(node)``, destroy, shut down.

    ``spin`` may return an exit status (``None`` or 0: success); see :func:`ros_session` for
    interrupts and ``errors``.
    """
    with ros_session(args, prog=prog, errors=errors, interrupted=interrupted):
        node = make_node()
        try:
            status = spin(node)
        finally:
            node.destroy_node()
        if status:
            sys.exit(status)
