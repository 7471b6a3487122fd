"""Codes and array layouts the exact engine's kernels share: the model vector (``M_*``,
``K_*``, ...), the carrier state (``S_*``), event kinds (``EV_*``, mirrored by the public
``EventKind``), event-function kinds (``F_*``), part phases, run statuses and the closed form's
table size. Numba kernels read plain integers fastest, so these stay module constants.
"""

# mypy: disable-error-code="misc, no-untyped-def"
from __future__ import annotations

EPS = 2.220446049250313e-16

# model vector
M_ONEWAY = 0  # carrier mass with one-way coupling (M + M_p + alpha*m)
M_BASE = 1  # carrier mass without parts (M + alpha*m), two-way coupling
DAMPING = 2
K_FWD = 3  # K_f*cos(theta)
K_BWD = 4
TRACK = 5
SWITCH = 6  # 0 displacement, 1 velocity
COUPLING = 7  # 0 one-way, 1 two-way
LOG_EVENTS = 8  # 0/1
MODEL_SIZE = 9

# carrier state vector
S_T = 0
S_X = 1
S_V = 2
S_MODE = 3  # +1 forward branch, -1 backward, 0 held (Filippov sliding, velocity switching only)
S_SEG = 4  # drive segment index
STATE_SIZE = 5

# event kinds (public EventKind mirrors these)
EV_BRANCH = 0
EV_SLIP_START = 1
EV_STICK = 2
EV_REVERSAL = 3
EV_DRIVE = 4
EV_EXIT = 5
EV_SLIDE_START = 6
EV_SLIDE_END = 7

# event-function kinds
F_BRANCH = 0
F_SLIDE_FWD = 1
F_SLIDE_BWD = 2
F_STICK_UP = 3
F_STICK_DOWN = 4
F_RELVEL = 5
F_EXIT = 6

STICK = 0
SLIP_FORWARD = 1
SLIP_BACKWARD = 2
EXITED = -1

STATUS_DONE = 0
STATUS_BUFFER_FULL = 1
STATUS_RESONANCE = 2
STATUS_STUCK = 3

NROWS = 10
N_ROT = 64  # output samples evaluated from one directly evaluated basis by exact shifts
