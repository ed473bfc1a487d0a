"""What the estimator says on /diagnostics: its fits by status, its latency, the stream's gaps."""

import collections
import math

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus

from mows.estimate.segments import SegmentAssembler
from mows_ros.diagnostics import Health

LATENCY_WINDOW = 500  # fits over which the latency percentiles are taken


class FitTally:
    """Counts fits by status name (and malformed input), and keeps the latest latencies."""

    def __init__(self):
        self._latency_ms = collections.deque(maxlen=LATENCY_WINDOW)
        self._counts = collections.Counter()
        self._per_probe = collections.Counter()  # probe_<id>_fits_ok, probe_<id>_fits_failed

    def count(self, what: str) -> None:
        self._counts[what] += 1

    def add(self, status_name: str, latency_ms: float, probe_id: int | None = None) -> None:
        """A fit published ``latency_ms`` after the message that completed its ring-down; of
        probe ``probe_id`` when several probes share the windows."""
        self._counts[status_name] += 1
        self._latency_ms.append(latency_ms)
        if probe_id is not None:
            self._per_probe[f"probe_{probe_id}_fits_{'ok' if status_name == 'OK' else 'failed'}"] += 1

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
                "blocks": assembler.blocks,
                "f00_hz": f00_hz,
                "f00_std_hz": f00_std_hz,
                **self._per_probe,
            },
        )
