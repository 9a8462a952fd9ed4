"""What a user may ask of hrlp, and why: the bounds the command line checks while it parses (before torch is imported)
and the configs check when they are built.

Each bound is there because a value beyond it is either meaningless (a negative seed, a fraction of a batch that
keeps no sample) or would keep the machine busy for minutes before the first line of output (20,000 MuJoCo
simulations to build, 1,000 sampling processes to start, a batch that does not fit in memory). This module imports
nothing but the standard library, so ``hrlp --help`` and every parse-time error stay fast.
"""

from __future__ import annotations

import math
import os
import socket

DEFAULT_EPISODE_STEPS = 300
"""The episode length of hrlp's arm tasks when none is given (the paper's: 300-500)."""

MAX_SEED = 2**32 - 1
"""Seeds are 32-bit, as NumPy's and Gymnasium's conventions (and torch's, portably) expect."""

MAX_NUM_ENVS = 1024
WHY_NUM_ENVS = (
    "each environment is a MuJoCo simulation built in this process before the first step (5-15 ms and about 1 MB "
    "each), and batched inference gains nothing beyond a few hundred"
)

MAX_BATCH_STEPS = 10_000_000
WHY_BATCH_STEPS = "a batch is held in memory (observations, actions, rewards: about 250 bytes a step); the paper's is 50,000"

MAX_STEPS = 10**12
WHY_STEPS = "a trillion environment steps is decades at a few thousand steps a second"

MAX_EPISODES = 100_000
WHY_EPISODES = "episodes run one after another in this process, and 100,000 episodes of 300 steps already take hours"

MAX_VIDEO_STEPS = 1_000_000
WHY_VIDEO_STEPS = "a million frames is 4.6 hours of video, rendered one by one"

MAX_MDPS = 100_000
WHY_MDPS = "each random MDP is searched for seconds; 100,000 already take days"

MAX_STATES = 1_000_000
WHY_STATES = "the hand-over states are collected one decision at a time and held in memory"

RAY_CONNECT_TIMEOUT_S = 5.0
"""Seconds to wait for a Ray cluster's address to accept a connection before giving up (Ray itself retries for
minutes)."""
RAY_HANDSHAKE_TIMEOUT_S = 1.5
"""Seconds a server at ``--address`` has to answer as a gRPC server does (Ray's answers in milliseconds)."""


def cores() -> int:
    """CPU cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        return os.cpu_count() or 1


def max_processes() -> int:
    """The most worker processes a command may start: twice the cores (at least 4)."""
    return max(4, 2 * cores())


def why_processes() -> str:
    """Why :func:`max_processes` bounds ``--workers``."""
    return (f"each worker is a process with its own torch and environments (about 300 MB), and more than twice this "
            f"machine's {cores()} cores only compete for them")  # fmt: skip


def count_problem(value: int, low: int | None, high: int | None = None, why: str = "", unit: str = "integer") -> str | None:
    """Why the integer ``value`` is not in ``[low, high]`` (None: unbounded), or None when it is; ``unit`` names what a
    positive value counts."""
    if low is not None and value < low:
        what = f"must be a positive {unit}" if low == 1 else f"must be at least {low}"
        return f"{what}, got {value}"
    if high is not None and value > high:
        return f"must be at most {high:,}, got {value:,}" + (f": {why}" if why else "")
    return None


def real_problem(value: float, low: float | None = None, high: float | None = None, low_open: bool = False,
                 high_open: bool = False) -> str | None:  # fmt: skip
    """Why the number ``value`` is not finite or not in the interval, or None when it is."""
    if not math.isfinite(value):
        return f"must be a finite number, got {value}"
    below = low is not None and (value <= low if low_open else value < low)
    above = high is not None and (value >= high if high_open else value > high)
    if below or above:
        if low is not None and high is not None:
            where = f"in {'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}"
        elif low is not None:
            where = f"{'>' if low_open else '>='} {low:g}"
        else:
            where = f"{'<' if high_open else '<='} {high:g}"
        return f"must be {where}, got {value:g}"
    return None


def fraction_problem(name: str, fraction: float, size: int, unit: str) -> str | None:
    """Why taking every ``round(1 / fraction)``-th of ``size`` samples keeps none but the first, or None (also for a
    fraction outside (0, 1], which its config refuses in its own words)."""
    if not 0 < fraction <= 1:
        return None
    if (stride := round(1 / fraction)) > size:
        return (f"{name} {fraction:g} keeps every {stride:,}th of the batch's {size:,} {unit}, fewer than one; it must be "
                f"at least 1/{size:,}")  # fmt: skip
    return None


def duration_problem(what: str, steps: int | None, episode: int) -> str | None:
    """Why a decision lasting ``steps`` low-level steps does not fit an ``episode``, or None."""
    if steps is not None and steps > episode:
        return (f"{what} ({steps:,}) is longer than an episode ({episode:,} steps): every such decision would last the "
                "rest of its episode")  # fmt: skip
    return None


def ray_address_problem(address: str, timeout_s: float = RAY_CONNECT_TIMEOUT_S) -> str | None:
    """Why the Ray cluster ``address`` (``HOST:PORT`` or ``ray://HOST:PORT``; ``auto`` and ``local`` are Ray's own and
    not checked here) cannot be used, or None when a gRPC server (Ray's GCS or client server) accepts a connection there
    within ``timeout_s`` and answers HTTP/2's preface within :data:`RAY_HANDSHAKE_TIMEOUT_S`."""
    if address in ("auto", "local"):
        return None
    hostport = address.removeprefix("ray://")
    host, sep, port = hostport.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        return f"--address must be HOST:PORT (or ray://HOST:PORT, auto, local), got {address!r}"
    hint = "start one there with 'ray start --head', or leave --address out to start a local Ray"
    try:
        conn = socket.create_connection((host.strip("[]"), int(port)), timeout=timeout_s)
    except OSError as e:
        reason = "no answer" if isinstance(e, TimeoutError) else (e.strerror or str(e))
        return f"cannot reach a Ray cluster at {address}: {reason} (within {timeout_s:g} s); {hint}"
    # Ray's GCS and client server speak gRPC: HTTP/2, which answers the client preface with a SETTINGS frame (a 9-byte
    # header whose 4th byte is its type, 4). Anything else listening there is not a Ray cluster.
    header = b""
    with conn:
        try:
            conn.settimeout(min(timeout_s, RAY_HANDSHAKE_TIMEOUT_S))
            conn.sendall(_HTTP2_PREFACE)
            while len(header) < 9 and (chunk := conn.recv(9 - len(header))):
                header += chunk
        except OSError:  # no answer within timeout_s, or the connection dropped
            pass
    if len(header) == 9 and header[3] == 4:
        return None
    answer = f"it answered {header!r}" if header else f"no answer within {min(timeout_s, RAY_HANDSHAKE_TIMEOUT_S):g} s"
    return f"{address} is not a Ray cluster: what listens there does not speak gRPC ({answer}); {hint}"


_HTTP2_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes([0, 0, 0, 4, 0, 0, 0, 0, 0])
"""HTTP/2's client connection preface followed by an empty SETTINGS frame."""
