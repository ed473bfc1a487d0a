"""What the estimator says on /diagnostics: its fits by status, its latency, the stream's gaps."""

import collections
import math

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus

from mows.estimate.segments import SegmentAssembler
from mows.estimate.stream import Estimated
from mows_ros.diagnostics import Health

LATENCY_WINDOW = 500  # fits over which the latency percentiles are taken


class FitTally:
    """Counts fits by status name (and malformed input), and keeps the latest latencies."""

    def __init__(self):
        self._latency_ms = collections.deque(maxlen=LATENCY_WINDOW)
        self._counts = collections.Counter()
        self._per_probe = collections.Counter()  # probe_<id>_fits_ok, probe_<id>_fits_failed
        self._unknown_probe_fits = 0

    def count(self, what: str) -> None:
        self._counts[what] += 1

    def add(self, estimated: Estimated, latency_ms: float, per_probe: bool) -> None:
        """A fit published ``latency_ms`` after the message that completed its ring-down, counted
        for its probe too with ``per_probe`` (the ``probes`` parameter names them), and as
        ``unknown_probe_fits`` when the window named a probe that parameter does not list."""
        status_name = estimated.fit.status.name
        self._counts[status_name] += 1
        self._latency_ms.append(latency_ms)
        self._unknown_probe_fits += estimated.unknown_probe
        if per_probe:
            self._per_probe[f"probe_{estimated.probe_id}_fits_{'ok' if status_name == 'OK' else 'failed'}"] += 1

    def health(self, last: str, assembler: SegmentAssembler, f00_hz: float, f00_std_hz: float) -> Health:
        latency = np.array(self._latency_ms) if self._latency_ms else np.array([math.nan])
        failed = sum(v for k, v in self._counts.items() if k != "OK")
        missing = assembler.missing_samples
        level = DiagnosticStatus.OK if not (failed or missing) else DiagnosticStatus.WARN
        return Health(
            level,
            last,
            {
                "fits_ok": self._counts["OK"],
                "fits_failed": failed,
                **{f"status_{k}": v for k, v in self._counts.items() if k != "OK"},
                "latency_p50_ms": float(np.percentile(latency, 50)),
                "latency_p99_ms": float(np.percentile(latency, 99)),
                "gaps": assembler.gaps,
                "missing_samples": missing,
                "late_windows": assembler.late_windows,
                "windows_before_start": assembler.windows_before_start,
                "device_restarts": assembler.device_restarts,
                "blocks": assembler.blocks,
                "f00_hz": f00_hz,
                "f00_std_hz": f00_std_hz,
                "unknown_probe_fits": self._unknown_probe_fits,
                **self._per_probe,
            },
        )
