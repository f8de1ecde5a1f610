"""Clock sync: every node estimates its offset to the tracker's clock.

NTP's on-wire exchange (RFC 5905, section 8) through a Zenoh queryable on
``optrack/<site>/clock``: the node sends its time ``t0``; the tracker notes
``t1`` when the request arrives and ``t2`` when it replies; the node reads
``t3`` on the reply. Then

    offset theta = ((t1 - t0) + (t2 - t3)) / 2      (tracker clock minus node clock)
    delay  delta = (t3 - t0) - (t2 - t1)            (round trip, minus the tracker's time)

The true offset lies within ``theta +- delta / 2``. Like NTP's clock filter
(RFC 5905, section 10) the node keeps the last samples and trusts the one of
minimum delay: its ``theta`` is the offset, ``delta / 2`` the uncertainty.
Nodes stamp detections with ``local clock + offset`` (tracker time).
"""

from __future__ import annotations

import collections
import dataclasses
import logging
import threading
import time
from collections.abc import Callable

from optrack.net.bus import Bus
from optrack.net.messages import ClockReply, ClockRequest
from optrack.params import Param, Params, Schema, register

__all__ = ["CLOCK_PARAMS", "ClockEstimate", "ClockServer", "ClockSync", "Sample", "local_clock"]

log = logging.getLogger("optrack.net.clock")

CLOCK_PARAMS = register(
    Schema(
        "clock",
        [
            Param(
                "period_s",
                2.0,
                min=0.1,
                max=600.0,
                step=0.1,
                unit="s",
                help="How often a node measures its offset to the tracker's clock.",
            ),
            Param(
                "burst",
                8,
                min=1,
                max=64,
                step=1,
                help="Request/response exchanges per measurement.",
            ),
            Param(
                "window",
                32,
                min=1,
                max=1024,
                step=1,
                help="Samples kept; the one of minimum round trip gives the offset.",
            ),
            Param(
                "timeout_s",
                0.5,
                min=0.01,
                max=10.0,
                step=0.01,
                unit="s",
                help="Wait this long for the tracker's reply to one request.",
            ),
            Param(
                "warn_ms",
                10.0,
                min=0.0,
                max=10000.0,
                step=0.5,
                unit="ms",
                help="Warn when the offset or its uncertainty is above this.",
            ),
            Param(
                "skew_s",
                0.0,
                min=-3600.0,
                max=3600.0,
                step=0.001,
                unit="s",
                help="Add this to the node's clock (to test clock sync); 0 in real use.",
            ),
        ],
        help="Clock sync of nodes to the tracker (NTP-style, minimum-delay filter).",
    )
)


def local_clock(params: Params | None = None) -> Callable[[], float]:
    """The node's wall clock in seconds, shifted by ``clock.skew_s`` when set."""
    skew = float(params.skew_s) if params is not None else 0.0
    if skew == 0.0:
        return time.time
    return lambda: time.time() + skew


@dataclasses.dataclass(frozen=True)
class Sample:
    """One exchange (RFC 5905 section 8 notation)."""

    t0: float
    t1: float
    t2: float
    t3: float

    @property
    def theta(self) -> float:
        """Offset: tracker clock minus node clock, s."""
        return ((self.t1 - self.t0) + (self.t2 - self.t3)) / 2.0

    @property
    def delta(self) -> float:
        """Round-trip delay without the tracker's processing time, s."""
        return max(0.0, (self.t3 - self.t0) - (self.t2 - self.t1))


@dataclasses.dataclass(frozen=True)
class ClockEstimate:
    """The node's best knowledge of the tracker's clock."""

    offset_s: float
    uncertainty_s: float
    samples: int
    measured_at: float  # node clock


class ClockServer:
    """The tracker side: answers clock requests with its receive and reply times."""

    def __init__(self, bus: Bus, clock: Callable[[], float] = time.time) -> None:
        self.clock = clock
        self.requests = 0
        bus.serve(bus.keys.clock, ClockRequest, self._answer)

    def _answer(self, request: ClockRequest) -> ClockReply:
        t1 = self.clock()
        self.requests += 1
        return ClockReply(t0=request.t0, t1=t1, t2=self.clock())


class ClockSync:
    """The node side: measures its offset every ``period_s`` in a background thread.

    Until the first answer the offset is 0 and :attr:`estimate` is None (the
    node is not synchronised and says so in its status).
    """

    def __init__(
        self,
        bus: Bus,
        params: Params | None = None,
        clock: Callable[[], float] | None = None,
        logger: logging.Logger = log,
    ) -> None:
        self.bus = bus
        self.params = params if params is not None else CLOCK_PARAMS.create()
        self.clock = clock if clock is not None else local_clock(self.params)
        self.estimate: ClockEstimate | None = None
        self._samples: collections.deque[Sample] = collections.deque(maxlen=int(self.params.window))
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._warned = False
        self._logger = logger
        self.failures = 0

    # ------------------------------------------------------------- reading
    @property
    def offset_s(self) -> float:
        estimate = self.estimate
        return estimate.offset_s if estimate is not None else 0.0

    def now(self) -> float:
        """The tracker's time now, as well as this node knows it."""
        return self.clock() + self.offset_s

    def to_tracker(self, local_t: float) -> float:
        """A time read on this node's clock, in tracker time."""
        return local_t + self.offset_s

    # ----------------------------------------------------------- measuring
    def exchange(self) -> Sample | None:
        """One request/response; None when the tracker did not answer in time."""
        t0 = self.clock()
        replies = self.bus.query(
            self.bus.keys.clock, ClockRequest(t0=t0), ClockReply, float(self.params.timeout_s)
        )
        t3 = self.clock()
        for reply in replies:
            if reply.t0 == t0:
                return Sample(t0, reply.t1, reply.t2, t3)
        return None

    def measure(self) -> ClockEstimate | None:
        """One burst of exchanges, then the minimum-delay estimate over the window."""
        if self._samples.maxlen != int(self.params.window):
            self._samples = collections.deque(self._samples, maxlen=int(self.params.window))
        got = 0
        for _ in range(int(self.params.burst)):
            if self._stop.is_set():
                break
            sample = self.exchange()
            if sample is None:
                break  # no tracker answering: do not wait out the whole burst
            self._samples.append(sample)
            got += 1
        if got == 0:
            self.failures += 1
            return self.estimate
        best = min(self._samples, key=lambda s: s.delta)
        self.estimate = ClockEstimate(
            best.theta, best.delta / 2.0, len(self._samples), self.clock()
        )
        self._check(self.estimate)
        return self.estimate

    def _check(self, estimate: ClockEstimate) -> None:
        limit = float(self.params.warn_ms) / 1000.0
        off = abs(estimate.offset_s) > limit
        loose = estimate.uncertainty_s > limit
        if (off or loose) and not self._warned:
            self._warned = True
            if off:
                side = "behind" if estimate.offset_s > 0 else "ahead of"
                self._logger.warning(
                    "this computer's clock is %.1f ms %s the tracker's (+-%.1f ms); detections "
                    "are restamped in tracker time, but run NTP (chrony) here to fix the clock.",
                    abs(estimate.offset_s) * 1000.0,
                    side,
                    estimate.uncertainty_s * 1000.0,
                )
            else:
                self._logger.warning(
                    "the clock offset to the tracker is only known to +-%.1f ms (slow network "
                    "round trips); detection times may be off by that much.",
                    estimate.uncertainty_s * 1000.0,
                )
        elif not (off or loose):
            self._warned = False

    # ----------------------------------------------------------- background
    def start(self) -> None:
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="clock-sync", daemon=True)
            self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self.measure()
            except Exception as error:  # the bus closing under us, a network fault
                if self._stop.is_set():
                    return
                self.failures += 1
                self._logger.debug("clock sync failed: %s", error)
            self._stop.wait(float(self.params.period_s))

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
