"""How every node's main() runs: init, build the node, spin until done or shut down, clean up.

On Jazzy ``rclpy.init()`` is no context manager: init, spin inside try, catch
``KeyboardInterrupt`` and ``ExternalShutdownException``, and ``rclpy.try_shutdown()`` in finally.
SIGINT, SIGTERM and SIGHUP (a closed terminal or ssh session) end the spin through our own
handler (see _StopOnSignal); a SIGHUP ignored when the node started (``nohup``) stays ignored.
A node's ``close()`` runs before the node is destroyed, so that the recorder finishes its bag
and every node logs its final report, and the process exits 0. A signal before that, while
Python imports the node (``id_learning.entry``) or ROS starts, ends it with one line and 130
(143 for SIGTERM). A signal while the node is made and waits on a pipe
(``robot_config:=<(...)``) ends that wait at once (``config_io.pipe_waits_stop_when``): the node
is refused, naming the file, and exits 2.
A ``--params-file`` that is no regular file is refused before ROS reads it
(``param_ros.params_file_kind``).
"""

from __future__ import annotations

import logging
import os
import signal
import sys
import threading
import time
from abc import abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import MISSING, fields

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.impl.rcutils_logger import RcutilsLogger
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future
from rclpy.utilities import ok, try_shutdown

from id_learning.config_io import pipe_waits_stop_when
from id_learning.entry import stopped_while_starting
from id_learning.errors import IdLearningError
from id_learning.nodes import param_ros

__all__ = ['NameClash', 'ShellNode', 'close_spun_node', 'make_executor', 'run_node']

SPIN_SLICE_S = 0.1
#: When a node first looks for another of its name on the graph, and how often after [s]: a
#: local graph query of tens of microseconds; discovery brings a peer within about a second.
NAME_CHECK_S = (1.0, 2.0)

_LOG = logging.getLogger(__name__)


class ShellNode(Node):
    """Base of the package's nodes: what run_node needs of them, and rclpy's API typed.

    ``done`` completes when the node has finished its work (a replay at the bag's end); nodes
    that run until shut down never complete it.
    """

    done: Future

    def get_logger(self) -> RcutilsLogger:
        """The node's logger (rclpy's method, with its type)."""
        logger: RcutilsLogger = Node.get_logger(self)
        return logger

    def destroy_node(self) -> None:
        """Release the node's ROS resources (rclpy's method, with its type)."""
        Node.destroy_node(self)

    @property
    def executor_kind(self) -> str:
        """The executor the node's ``executor`` parameter names (every node declares one)."""
        return str(Node.get_parameter(self, 'executor').value)

    @abstractmethod
    def close(self) -> None:
        """Finish work (files, reports); called once, before destroy_node."""


class NameClash:
    """Another node of this node's full name on the graph, said once in one error line.

    Two nodes of one name share their parameters' and services' names: ``ros2 param set``
    reaches either of them, and which one is not said. ROS lets the second start; both are
    told, each with the remedy (``-r __node:=NAME``). ``poll`` looks ``first_s`` after the start,
    then every ``every_s``, until it finds one.
    """

    def __init__(
        self,
        node: Node,
        now_s: Callable[[], float],
        first_s: float = NAME_CHECK_S[0],
        every_s: float = NAME_CHECK_S[1],
    ) -> None:
        self.node, self._now_s, self._every_s = node, now_s, every_s
        self.next_s = now_s() + first_s
        self.found = False

    def poll(self) -> bool:
        """Look when a check is due; whether a clash is found (now or before)."""
        if self.found or self._now_s() < self.next_s:
            return self.found
        return self.check_now()

    def check_now(self) -> bool:
        """Look now, whatever the schedule (a node whose work may end before the first look)."""
        if self.found:
            return True
        self.next_s = self._now_s() + self._every_s
        node = self.node
        me = (node.get_name(), node.get_namespace())
        if node.get_node_names_and_namespaces().count(me) > 1:
            self.found = True
            full = node.get_fully_qualified_name()
            node.get_logger().error(
                f'another node is also named {full}: its parameters, services and reports '
                "cannot be told from this one's (a parameter set may reach either); give each "
                'node its own name: --ros-args -r __node:=NAME'
            )
        return self.found


def make_executor(name: str) -> rclpy.executors.Executor:
    """'single_threaded' (rclpy's) or 'events' (the experimental C++ events executor)."""
    if name == 'events':
        from rclpy.experimental.events_executor import EventsExecutor

        return EventsExecutor()
    return SingleThreadedExecutor()


class _StopOnSignal:
    """SIGINT/SIGTERM/SIGHUP end the spin while the context is still valid, so close() can log.

    rclpy's own handlers would shut the context down first; the node's final report would then
    fail to reach /rosout. Further signals are ignored while the node closes (a recorder must
    finish its bag); SIGKILL remains the way to end a node that hangs. SIGHUP, whose default
    would end the process at once (a torn bag, an adaptation's state lost), stops the node like
    SIGTERM, unless it was ignored when the node started (``nohup``: meant to outlive the
    terminal).
    """

    def __init__(self) -> None:
        self.event = threading.Event()
        numbers = [signal.SIGINT, signal.SIGTERM]
        if signal.getsignal(signal.SIGHUP) is not signal.SIG_IGN:
            numbers.append(signal.SIGHUP)
        self._previous = {number: signal.signal(number, self._handle) for number in numbers}

    def _handle(self, number: int, frame: object) -> None:
        self.event.set()

    def restore(self) -> None:
        """Put the handlers before back, unless a signal stopped the node.

        The process is then ending: a repeated Ctrl-C must not end it by signal after its bag
        and its report are done.
        """
        for number, handler in self._previous.items():
            # Ignored, not handled: Python puts its handlers back to the default (death by
            # signal) while the interpreter shuts down, but leaves SIG_IGN as it is.
            signal.signal(number, signal.SIG_IGN if self.event.is_set() else handler)


def close_spun_node(
    node: rclpy.node.Node,
    executor: rclpy.executors.Executor,
    thread: threading.Thread,
    stop: threading.Event,
    timeout_s: float = 5.0,
) -> None:
    """Stop a node a thread of this process spins, then destroy it and shut its context down.

    The spin thread ends first and the executor lets go of the node before the node is destroyed:
    a node destroyed while it is spun, or still held by an executor, can crash the whole process
    in the middleware (ros2/rclpy#663).

    A spin thread still running after ``timeout_s`` is logged and the node left to the process's
    exit (``close`` runs in ``finally`` blocks: raising would hide what is being handled).
    """
    stop.set()
    thread.join(timeout_s)
    if thread.is_alive():
        _LOG.warning('%s: its spin thread did not stop in %g s; left to exit', node.get_name(),
                     timeout_s)  # fmt: skip
        return
    executor.remove_node(node)
    node.destroy_node()
    executor.shutdown()
    node.context.try_shutdown()


def print_usage(name: str, config_class: type) -> None:
    """Print how to run a node and its parameters with defaults and descriptions."""
    print(
        f'usage: ros2 run id_learning {name} --ros-args [-p NAME:=VALUE ...] [--params-file FILE]'
    )
    print(f'\nparameters of {name} (see config/nodes.yaml):')
    for item in fields(config_class):
        default = item.default if item.default is not MISSING else '(required)'
        if item.default is MISSING and item.default_factory is not MISSING:
            default = item.default_factory()
        description = item.metadata.get('description', '')
        print(f'  {item.name} = {default!r}\n      {description}')


def wants_help(args: Sequence[str] | None) -> bool:
    """Whether -h/--help comes before any --ros-args."""
    words = list(sys.argv[1:] if args is None else args)
    if '--ros-args' in words:
        words = words[: words.index('--ros-args')]
    return '-h' in words or '--help' in words


def run_node(
    make_node: Callable[[], ShellNode],
    args: Sequence[str] | None,
    *,
    name: str = '',
    config_class: type | None = None,
) -> int:
    """Create a node and spin it until its ``done`` future completes or a signal arrives.

    Returns:
        The process exit status: 0, or 2 when the node could not start (bad parameters,
        missing files, a params file that is no regular file, a signal while it waited on a
        pipe), with the reason logged; 130 after one line when Ctrl-C came while ROS
        started, before the node was being made (during the imports, ``id_learning.entry``
        says so alike).
    """
    if config_class is not None and wants_help(args):
        try:
            print_usage(name, config_class)
            sys.stdout.flush()
        except BrokenPipeError:  # '--help | head': quietly, as the Python docs say
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
            os.close(devnull)
            return 128 + signal.SIGPIPE
        return 0
    problem = param_ros.params_file_kind(args)  # before rcl reads it (a FIFO: without end)
    if problem:
        print(f'error: {name or "node"}: {problem}', file=sys.stderr)
        return 2
    try:
        rclpy.init(
            args=None if args is None else list(args),
            signal_handler_options=SignalHandlerOptions.NO,
        )
        # From here a signal is noted, never raised: a node being made is made whole (a
        # recorder's bag opened), then closed with its report.
        stop = _StopOnSignal()
    except RuntimeError as err:  # rclpy's RCLError: an unreadable --params-file, bad --ros-args
        print(f'error: {name or "node"}: ROS 2 could not start it: {err}', file=sys.stderr)
        return 2
    except KeyboardInterrupt as err:  # Ctrl-C while ROS starts: nothing of the node exists yet
        try_shutdown()
        return stopped_while_starting(name or 'node', err)
    node: ShellNode | None = None
    status = 0
    param_ros.COMMAND_LINE = None if args is None else list(args)  # its -p and params files
    try:
        # A signal is noted, not raised: a wait on a pipe (robot_config:=<(...)) checks for it.
        with pipe_waits_stop_when(stop.event.is_set):
            node = make_node()
        spinner = make_executor(node.executor_kind)
        spinner.add_node(node)
        # One watch per node: a node that looks itself at its own moments shares it.
        clash = getattr(node, 'name_clash', None) or NameClash(node, time.monotonic)
        # Short waits: Python runs signal handlers only between them. (Not
        # spin_until_future_complete with a timeout: each call adds a callback to the future.)
        while not (node.done.done() or stop.event.is_set()) and ok():
            spinner.spin_once(timeout_sec=SPIN_SLICE_S)
            clash.poll()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except IdLearningError as err:
        logging.getLogger('id_learning.nodes').critical('%s', err)
        print(f'error: {err}', file=sys.stderr)
        status = 2
    finally:
        try:
            if node is not None:
                try:
                    node.close()
                finally:
                    node.destroy_node()
        finally:
            stop.restore()
            try_shutdown()
    return status
