"""The state records the exact engine's kernels pass around: named tuples of arrays (numba
compiles attribute access to a plain field read, so a record costs nothing over its arrays).

The kernels' public entry points (:func:`~feeder_ros.physics.exact.global_loop.advance`,
:func:`~feeder_ros.physics.exact.group_march.advance_groups`) take their arrays one by one (the
callers in :mod:`feeder_ros.physics.live_simulator` own them as named arrays) and bundle them into
records for the loops they call.
"""

from __future__ import annotations

from collections import namedtuple

Groups = namedtuple("Groups", ["L", "D", "mass", "u", "y", "slip", "lead", "phase", "head"])
Groups.__doc__ = """Part groups (parts with the same friction that move together): stick limit
``L = mu_s*g*kappa`` and kinetic ``D = mu_d*g*kappa``, summed mass, velocity ``u`` at the
piece's start, track offset ``y`` and slip total of the group, its lead part's offset (``lead``),
phase (STICK, SLIP_FORWARD, SLIP_BACKWARD) and first member (``head``, -1: empty)."""

Members = namedtuple("Members", ["group", "next", "o", "mass", "slip0", "exit_t"])
Members.__doc__ = """Parts, each a member of one group (``group``, -1 once exited; ``next``: the
next member of the same group, -1 at the end): its offset ``o`` from the group's track offset,
its mass, its slip total when it joined the group (``slip0``) and its exit time."""

Functions = namedtuple(
    "Functions", ["kind", "group", "row", "sgn", "c0", "c1", "c2", "skip", "zero", "evaluated"]
)
Functions.__doc__ = """A loop's event functions ``sgn*row(tau) + c0 + c1*s + c2*s^2``
(``s`` the time since the sub-piece's start ``ts``), one slot each: their ``F_*`` kind, group
(part events), coefficients, and the search's state: ``skip`` (provably positive before this
time), ``zero`` (no root on this piece) and ``evaluated`` (stepped at the current stop)."""

BoundRows = namedtuple("BoundRows", ["vals", "bnds", "hbnds", "abs_a", "abs_b", "amp", "R"])
BoundRows.__doc__ = """Scratch rows of the certified search: each row's value at the current stop,
its bound (``bnds``) and its homogeneous terms' bound (``hbnds``) over the rest of the piece, and
the per-row bound terms of :func:`~feeder_ros.physics.exact.search._bound_terms`."""

ShiftTable = namedtuple("ShiftTable", ["key", "rot", "n"])
ShiftTable.__doc__ = """Per carrier branch (slot 0 forward or held, 1 backward): the basis
parameters ``(sigma, lambda, w)`` the table is for (``key``), the basis shifted by ``j*h_nom``
(``rot[slot, :, j]``: C, S, sin, cos) and the number of shifts filled (``n``)."""
