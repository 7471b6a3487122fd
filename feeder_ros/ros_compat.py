"""The one place where code differs between the supported ROS 2 distributions (Jazzy, Kilted).

feeder_ros runs on ROS 2 Jazzy (rclpy 7.x, the default) and Kilted (rclpy 9.x). Everything
that depends on which rclpy is installed goes through this module, so the nodes and tools stay
free of version checks:

- :class:`RosSession` is ``rclpy.init`` as a context manager. Kilted's ``rclpy.init`` returns one
  (``InitContextManager``); Jazzy's returns ``None`` and leaves the shutdown to the caller.
- :func:`ros_distro` names the distribution the installed rclpy belongs to, without importing it
  (the ROS-free bag writer records it in ``metadata.yaml``).
- :data:`AnyParameter` is the type of an ``rclpy.parameter.Parameter`` of any value for the type
  checker: Kilted's ``Parameter`` is generic (``Parameter[Any]``), Jazzy's is not.
"""

from __future__ import annotations

import os
from importlib import metadata
from types import TracebackType
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from typing import TypeAlias

    from rclpy.context import Context
    from rclpy.parameter import Parameter
    from rclpy.signals import SignalHandlerOptions

    # Kilted: generic; Jazzy: not (there the ignore applies and the alias is plain Parameter)
    AnyParameter: TypeAlias = Parameter[Any]  # type: ignore[type-arg,unused-ignore]

#: rclpy's major version in each supported distribution (ros/rclpy's branches).
RCLPY_MAJOR_BY_DISTRO = {"jazzy": 7, "kilted": 9}


def rclpy_major() -> int | None:
    """The installed rclpy's major version, read from its package metadata (no import): the PyPI
    wheels are ``ros-rclpy``, a ROS install's is ``rclpy``; ``None`` when neither is found."""
    for distribution in ("ros-rclpy", "rclpy"):
        try:
            return int(metadata.version(distribution).split(".")[0])
        except (metadata.PackageNotFoundError, ValueError):
            continue
    return None


def ros_distro() -> str:
    """The ROS 2 distribution in use: ``$ROS_DISTRO`` when a ROS environment set it, else the
    one the installed rclpy belongs to (``jazzy``/``kilted``), else ``"unknown"``."""
    named = os.environ.get("ROS_DISTRO", "").strip()
    if named:
        return named
    major = rclpy_major()
    for distro, distro_major in RCLPY_MAJOR_BY_DISTRO.items():
        if major == distro_major:
            return distro
    return "unknown"


class RosSession:
    """``rclpy.init`` for a block: ``with RosSession(args) as session: ... session.context``.

    Initialises ``context`` (rclpy's default context when ``None``) on construction, so a bad
    ROS argument raises ``RCLError`` before the ``with`` block, as Kilted's ``rclpy.init`` does.
    Leaving the block shuts the context down (if it still runs) and uninstalls the signal
    handlers that were installed for it, on every distribution.
    """

    def __init__(
        self,
        args: list[str] | None = None,
        *,
        context: Context | None = None,
        signal_handler_options: SignalHandlerOptions | None = None,
    ) -> None:
        import rclpy
        from rclpy.utilities import get_default_context

        # Jazzy's init returns None, Kilted's an InitContextManager (which shuts down on exit)
        init: Any = rclpy.init
        manager = init(args=args, context=context, signal_handler_options=signal_handler_options)
        self._manager = manager
        self.context: Context = (
            manager.context
            if manager is not None
            else (get_default_context() if context is None else context)
        )
        self._default = context is None or context is get_default_context()
        self._handlers_installed = (signal_handler_options is None and self._default) or (
            signal_handler_options is not None and signal_handler_options.name != "NO"
        )

    def __enter__(self) -> RosSession:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        if self._manager is not None:
            self._manager.__exit__(exc_type, exc, traceback)
            return
        # Jazzy: what Kilted's InitContextManager.__exit__ does
        from rclpy.signals import uninstall_signal_handlers
        from rclpy.utilities import try_shutdown

        try_shutdown(context=None if self._default else self.context)
        if self._handlers_installed:
            uninstall_signal_handlers()
