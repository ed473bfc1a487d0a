"""The probes one estimator tells apart in each ring-down window: the ``probes`` text of the
estimator's parameters read into each probe's id, constants, f00 and place, and made into the
fit's lines (:class:`mows.estimate.ringdown.ProbeLine`); and the lines of a scene's placed
probes (:func:`probe_lines`).

The text is a YAML mapping from probe id (0–255) to the probe, given as its f00 in Hz, as a
probe constants file (:meth:`mows.physics.probe.Probe.from_yaml`, whose f00 it takes), or as a
mapping with any of ``f00_hz``, ``f00_std_hz``, ``probe_file`` and ``position_m``::

    {0: 112.48, 1: probes/b.yaml, 2: {f00_hz: 100.2, position_m: [0.0, 0.05, 0.0]}}

A probe given by its f00 alone is the estimator's own probe (``probe_file``) with the spring
that gives it that f00 (:func:`with_f00`), its lever, moment, inertia and damping kept; its
f00 is then also the zero-field frequency its shifts are counted from. ``position_m`` is the probe's
magnet at rest relative to the single probe's place before the fluxgates, in the rotation
plane's frame (x = e1 towards the sensors' side, y = e2); each probe is turned about its own
magnet to the θ0 the driver announces for it (``probe_theta0_rad`` of a ring-down that lists its
probes, :func:`window_probes`; else the one θ0 of the window). A probe orbiting a shared axis is
not modelled. An empty text lists none: a node then tells apart its own probe alone, as probe 0
(:func:`mows.estimate.settings.node_probes`, the one place where a text is made a set).

At most :data:`MAX_PROBES` probes, each line at least :data:`MIN_SEPARATION_HZ` from the
others: closer lines are not told apart in a window of a second or less (docs/multi_probe.md).
The probes whose ``position_m`` is given must lie as far apart as a scene's
(:func:`mows.physics.coupling.check_apart`); those without one share the single probe's place.
The text is read as our YAML files are (:func:`mows.physics.schema.parse_yaml`: ``1e2`` is a
number), and a refusal names the key path (``probes[2].position_m = …``) and the value.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from typing import Any

from mows.estimate.ringdown import FitOptions, ProbeLine
from mows.estimate.segments import RingdownWindow
from mows.physics.coupling import PlacedProbe, check_apart
from mows.physics.fluxgate import FluxgatePair, pickup_harmonics, pickup_scale_t
from mows.physics.multitone import MAX_PROBES
from mows.physics.pose import Pose
from mows.physics.probe import Probe
from mows.physics.schema import SchemaError, at, is_number, parse_yaml, refused, vector3

MIN_SEPARATION_HZ = 1.0
KEYS = ("f00_hz", "f00_std_hz", "probe_file", "position_m")


@dataclasses.dataclass(frozen=True)
class ProbeEntry:
    """One probe of the set: its id, constants, the f00 its shift is counted from (± σ), and
    its place relative to the single probe's (m). Also each member of the model lab's probe set
    (:class:`mows.lab.data.probe_rows.ProbeSet`), there at its constants' f00."""

    probe_id: int
    probe: Probe
    f00_hz: float
    f00_std_hz: float = 0.0
    position_m: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def line(self, theta0_rad: float, pair: FluxgatePair | None, channels: str, tone_hz: float = math.nan) -> ProbeLine:
        """Its line in the fit at θ0 (:func:`probe_line`, at its place), looked for at
        ``tone_hz`` (the driver's tone: its resonance in the present field), else at f00."""
        expected_hz = tone_hz if math.isfinite(tone_hz) and tone_hz > 0 else self.f00_hz
        pose = Pose(theta0_rad=theta0_rad, magnet_position_m=self.position_m)
        return probe_line(self.probe_id, self.probe, pose, expected_hz, pair, channels)


def own_probe_entry(probe: Probe, f00_hz: float = 0.0, f00_std_hz: float = 0.0) -> ProbeEntry:
    """A node's own probe (its ``probe_file``) as probe 0 of its set, at ``f00_hz`` (0: the
    probe's) ± ``f00_std_hz``."""
    return ProbeEntry(0, probe, f00_hz if f00_hz > 0 else probe.f00_hz, f00_std_hz)


def probe_line(
    probe_id: int, probe: Probe, pose: Pose, expected_hz: float, pair: FluxgatePair | None, channels: str
) -> ProbeLine:
    """The line of ``probe`` at ``pose`` in the fit: the exact pickup of its magnet swinging on
    its lever before ``pair`` (the fitted channel combination) with its absolute scale, or the
    paper's single term (``pair`` None); its line expected at ``expected_hz``."""
    if pair is None:
        return ProbeLine(probe_id, pose.theta0_rad, expected_hz, None, probe.damping_per_s)
    moment = probe.moment_am2
    pickup = tuple(pickup_harmonics(pair, pose, probe.lever_m, moment, combine=channels))
    scale_t = pickup_scale_t(pair, pose.magnet_position_m, moment, channels)
    return ProbeLine(probe_id, pose.theta0_rad, expected_hz, pickup, probe.damping_per_s, scale_t)


def probe_lines(
    pair: FluxgatePair,
    placed: Sequence[PlacedProbe],
    probe_ids: Sequence[int],
    expected_frequency_hz: Sequence[float],
    channels: str = FitOptions.channels,
) -> list[ProbeLine]:
    """One line per probe of a scene: ``placed[k]`` (at its present θ0) with id
    ``probe_ids[k]``, its line expected at ``expected_frequency_hz[k]`` (its tone's)."""
    return [
        probe_line(int(probe_id), p.probe, p.pose, float(f), pair, channels)
        for p, probe_id, f in zip(placed, probe_ids, expected_frequency_hz)
    ]


@dataclasses.dataclass(frozen=True)
class WindowProbe:
    """A probe a ring-down window holds: its id, its own θ0 and tone (NaN: none announced), and
    its entry in the set (None: an id the set does not list)."""

    probe_id: int
    theta0_rad: float
    tone_hz: float
    entry: ProbeEntry | None

    def unknown_message(self, probes: Sequence[ProbeEntry]) -> str:
        known = ", ".join(str(e.probe_id) for e in probes)
        return f"probe {self.probe_id} rang in this window but is not in the probes parameter (listed: {known})"


def window_probes(probes: Sequence[ProbeEntry], window: RingdownWindow) -> list[WindowProbe]:
    """The probes ``window`` holds, in id order: those it lists (``probe_ids``), each at its
    own ``probe_theta0_rad`` and tone. A window that lists none (recorded before excitations
    listed their probes) was rung by one tone at one θ0: every probe of the set is at the
    window's θ0, and the one whose f00 is nearest the window's tone (that tone's probe) is
    looked for at it, the others at their f00."""
    if not window.probe_ids:
        tone_hz = window.excitation_frequency_hz
        driven = min(probes, key=lambda e: abs(e.f00_hz - tone_hz)) if math.isfinite(tone_hz) else None
        return [WindowProbe(e.probe_id, window.theta0_rad, tone_hz if e is driven else math.nan, e) for e in probes]
    known = {e.probe_id: e for e in probes}
    listed = zip(window.probe_ids, window.probe_theta0_rad, window.probe_frequency_hz)
    return sorted(
        (WindowProbe(int(k), float(theta0), float(tone), known.get(int(k))) for k, theta0, tone in listed),
        key=lambda p: p.probe_id,
    )


def read_probe_set(text: str, own_probe: Probe, read_probe: Callable[[str], Probe]) -> tuple[ProbeEntry, ...]:
    """The probes of ``text`` (module docstring) in order of id; () for an empty text.
    ValueError naming the entry and what is wrong; ``read_probe`` reads a probe file (its
    errors pass through)."""
    if not text.strip():
        return ()
    with at("probes"):
        given = parse_yaml(text)
    if not isinstance(given, dict) or not given:
        raise refused("probes", given, "is not a mapping of probe id to f00 (Hz) or probe file")
    if len(given) > MAX_PROBES:
        raise SchemaError("probes", f"lists {len(given)} probes; at most {MAX_PROBES} share a window")
    for key in given:
        if not is_number(key) or not isinstance(key, int) or not 0 <= key <= 255:
            raise SchemaError("probes", f"probe id {key!r} is not an integer in 0–255")
    placed = {}
    with at("probes"):
        entries = []
        for key, value in sorted(given.items()):
            with at(key):
                entry, placed_here = _entry(key, value, own_probe, read_probe)
            entries.append(entry)
            if placed_here:
                placed[key] = PlacedProbe(entry.probe, Pose(magnet_position_m=entry.position_m))
    check_apart(list(placed.values()), [f"probes[{key}].position_m" for key in placed])
    f00s = sorted((e.f00_hz, e.probe_id) for e in entries)
    for (low, a), (high, b) in zip(f00s, f00s[1:]):
        if high - low < MIN_SEPARATION_HZ:
            raise ValueError(
                f"probes {a} and {b}: f00 {low:g} and {high:g} Hz are closer than {MIN_SEPARATION_HZ:g} Hz "
                "(docs/multi_probe.md: keep lines at least 5/T apart)"
            )
    return tuple(entries)


def _entry(key: int, value: object, own_probe: Probe, read_probe: Callable[[str], Probe]) -> tuple[ProbeEntry, bool]:
    """The entry of probe ``key``, and whether its place is given."""
    if is_number(value):
        value = {"f00_hz": value}
    elif isinstance(value, str):
        value = {"probe_file": value}
    if not isinstance(value, dict) or set(value) - set(KEYS):
        raise refused("", value, f"is not an f00 in Hz, a probe file or a mapping of {', '.join(KEYS)}")
    probe = read_probe(value["probe_file"]) if "probe_file" in value else own_probe
    f00_hz = _number("f00_hz", value.get("f00_hz", probe.f00_hz), 0.0, 10_000.0)
    if "probe_file" not in value:
        probe = with_f00(probe, f00_hz)
    f00_std_hz = _number("f00_std_hz", value.get("f00_std_hz", 0.0), 0.0, 10.0)
    x, y, z = (float(v) for v in vector3("position_m", value.get("position_m", (0.0, 0.0, 0.0))))
    return ProbeEntry(key, probe, f00_hz, f00_std_hz, (x, y, z)), "position_m" in value


def with_f00(probe: Probe, f00_hz: float) -> Probe:
    """``probe`` with the spring that gives it ``f00_hz`` (Eq. S1 at B = G = 0: kM = J·((2π·f00)² + δ²)),
    its other constants kept: hand-made probes differ most in their cantilevers' stiffness."""
    spring = probe.inertia_kgm2 * ((2.0 * math.pi * f00_hz) ** 2 + probe.damping_per_s**2)
    return dataclasses.replace(probe, spring_nm_per_rad=spring)


def _number(name: str, value: Any, low: float, high: float) -> float:
    """``value`` as a float in [low, high] (f00 above ``low``), else ValueError naming it."""
    positive = name != "f00_hz" or value > low if is_number(value) else False
    if not (is_number(value) and math.isfinite(value) and low <= value <= high and positive):
        bounds = f"({low:g}, {high:g}]" if name == "f00_hz" else f"[{low:g}, {high:g}]"
        raise refused(name, value, f"is outside {bounds}")
    return float(value)


def probe_frame_id(base: str, probe_id: int, named: bool) -> str:
    """The frame of probe ``probe_id``: where the ``probes`` setting names the probes, the frame
    name ``base`` with the id appended (``mows_probe`` → ``mows_probe_2``); ``base`` itself for
    a node's own probe (not named)."""
    return f"{base}_{probe_id}" if named else base
