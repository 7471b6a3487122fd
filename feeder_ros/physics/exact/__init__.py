"""The exact event-driven engine of the sharp feeder model (numba kernels).

No time step: between events the carrier's linear ODE is solved in closed form and every event
(stiffness branch, sliding bounds, stick limits, relative velocities, track end) is found by a
certified root search that cannot step over a root; the only errors are floating-point round-off.

- :mod:`.layout`: codes and array layouts shared by the kernels;
- :mod:`.records`: the state records (named tuples of arrays) the steps share;
- :mod:`.closed_form`: coefficient rows, the homogeneous basis, its bounds and exact shifts;
- :mod:`.search`: the certified root search;
- :mod:`.event_steps`: the event steps both loops share;
- :mod:`.sampling`: output samples and part totals;
- :mod:`.global_loop`: :func:`advance`, the reference event loop (any coupling);
- :mod:`.many_runs`: :func:`advance_many`, independent runs in parallel;
- :mod:`.recorded_pieces`, :mod:`.group_march`, :mod:`.ordering`: the group march, an
  accelerator for one-way coupling, and the time order of its events.

:mod:`feeder_ros.physics.simulation` is the public API over these kernels.
"""
