"""The physical channels through which a term beyond the catalog can act, and their Jacobians.

A channel is one quantity of the exact potential U(θ) (docs/physics.md §4) that a plugin can
change row by row (:mod:`mows.lab.model.plugins`): the moment's scale, the spring, a field at the
magnet in the lab frame (x, y) or the probe frame (along, across the lever), the probe's angle, the
magnet's position on the lever (along, across), an added energy (a moment induced along the
lever, −½·α·(u·B)²; a stiffening hinge, ¼·k3·θ⁴), and, last, an additive frequency (a readout
term, no physics). A term of the search is a channel times
a monomial x of the covariates (:mod:`.library`): the channel's value on row i is p·x_i, and since
each row's frequency depends on its own value only, the term's column is the channel's Jacobian
∂f_i/∂p times x_i, to first order in p (exact for the frequency). One model evaluation per channel
gives every monomial's column. A frequency term of degree 3 (B∥·I²) is then a channel term of
degree 2 (the moment × I²).

A channel takes only the covariates it can follow (:attr:`Channel.excludes`): none takes the
stage's angle (the field channels make the harmonics) or the ring-down's swing (a swing acts
through the shape of the energy, not through a moment or a spring that knows it), and the spring
takes no field (a spring that follows the field is a magnetic energy: the moment or an added
energy). The frequency, the last resort, takes them all.

The channels are listed in library order: of terms of one degree that the rows cannot tell apart
the first is kept (:func:`mows.lab.diagnosis.discovery.search.library_terms`), so physics comes
before the readout term, the simplest physics before the more particular, and a turned probe
before a field that turns with it (a torque across the lever moves the rest angle as a turn does).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence

import numpy as np

from mows.lab.data.table import MeasurementTable
from mows.lab.model.configuration import Configuration, LeverArc
from mows.lab.model.effects import MECHANICS, ORIENTATION, READOUT, Effect, Parameter
from mows.lab.model.least_squares import FitResult
from mows.physics.probe import Probe

Edit = Callable[[Configuration, Probe, float], None]


@dataclasses.dataclass(frozen=True)
class Channel:
    """A quantity of the potential a term can change: its name, the plugin output that writes it,
    the plugin parameter's name and unit (per unit of the monomial), the step of its Jacobian, how
    a value edits a row's configuration, the plugin's returned value (``{value}`` the expression
    p·x over ``rows``), and what would tell it apart from another channel (a measurement)."""

    name: str
    output: str
    parameter: str
    unit: str
    step: float
    stage: int
    edit: Edit
    returned: str
    tells_apart: str
    excludes: frozenset[str] = frozenset({"angle", "swing"})  # kinds of covariates it cannot follow

    def jacobian_effect(self) -> Effect:
        """The channel as an effect of one constant parameter (its Jacobian's signature)."""
        edit = self.edit
        return Effect(
            f"channel_{self.name}",
            self.name,
            "",
            "",
            (Parameter(self.parameter, self.unit, -1e6 * self.step, 1e6 * self.step, self.step),),
            lambda config, rows, probe, value: edit(config, probe, value),
            self.stage,
            origin="discovery",
        )


def _in_plane(config: Configuration, vector: np.ndarray) -> None:
    config.field_t = config.field_t + np.concatenate([vector, np.zeros(vector.shape[:-1] + (1,))], axis=-1)


def _moment(config: Configuration, probe: Probe, value: float) -> None:
    config.moment_factor = config.moment_factor * (1.0 + value)


def _spring(config: Configuration, probe: Probe, value: float) -> None:
    config.spring_nm_per_rad = config.spring_nm_per_rad + value


def _field_x(config: Configuration, probe: Probe, value: float) -> None:
    _in_plane(config, np.array([value, 0.0]))


def _field_y(config: Configuration, probe: Probe, value: float) -> None:
    _in_plane(config, np.array([0.0, value]))


def _field_along(config: Configuration, probe: Probe, value: float) -> None:
    theta0 = config.theta0_rad
    _in_plane(config, value * np.stack([np.cos(theta0), np.sin(theta0)], -1))


def _field_across(config: Configuration, probe: Probe, value: float) -> None:
    theta0 = config.theta0_rad
    _in_plane(config, value * np.stack([-np.sin(theta0), np.cos(theta0)], -1))


def _angle(config: Configuration, probe: Probe, value: float) -> None:
    config.theta0_rad = config.theta0_rad + value


def _magnet(config: Configuration, offset: np.ndarray) -> None:
    before = np.zeros((len(config.theta0_rad), 3)) if config.magnet_offset_m is None else config.magnet_offset_m
    config.magnet_offset_m = before + offset


def _magnet_along(config: Configuration, probe: Probe, value: float) -> None:
    _magnet(config, np.array([value, 0.0, 0.0]))


def _magnet_across(config: Configuration, probe: Probe, value: float) -> None:
    _magnet(config, np.array([0.0, value, 0.0]))


def _add_energy(config: Configuration, energy: np.ndarray) -> None:
    config.energy_j = energy + (0.0 if config.energy_j is None else config.energy_j)


def induced_energy_j(arc: LeverArc) -> np.ndarray:
    """−½·(u·B)² along the arc, per A·m²/T of induced moment (n, nodes)."""
    return -0.5 * (arc.field_t * arc.direction).sum(-1) ** 2


def _induced(config: Configuration, probe: Probe, value: float) -> None:
    _add_energy(config, value * induced_energy_j(LeverArc.of(config, probe)))


def _quartic(config: Configuration, probe: Probe, value: float) -> None:
    arc = LeverArc.of(config, probe)
    _add_energy(config, np.broadcast_to(value * 0.25 * arc.theta_rad**4, arc.field_t.shape[:2]))


def _frequency(config: Configuration, probe: Probe, value: float) -> None:
    config.frequency_hz = config.frequency_hz + value


_ALONG = "np.stack([np.cos(rows.theta0_rad), np.sin(rows.theta0_rad)], -1)"
_ACROSS = "np.stack([-np.sin(rows.theta0_rad), np.cos(rows.theta0_rad)], -1)"
_PER_ROW = "np.reshape({value}, (-1, 1))"  # a per-row value beside a vector or the arc's nodes

CHANNELS = (
    Channel(
        "moment", "moment_scale", "c", "1", 1e-6, MECHANICS, _moment, "{value}",
        "a gradient or a field reversal (a moment acts in every magnetic term, m·B and l·m·G alike; "
        "a field error only where that field is)",
    ),
    Channel(
        "spring", "stiffness_nm_per_rad", "k_nm_per_rad", "N·m/rad", 1e-12, MECHANICS, _spring, "{value}",
        "the zero-field frequency f00 at the same covariate (only the spring acts without a field)",
        frozenset({"angle", "swing", "field", "field_z", "gradient"}),
    ),
    Channel(
        "angle", "angle_offset_rad", "offset_rad", "rad", 1e-7, ORIENTATION, _angle, "{value}",
        "the probe's angle measured optically, or a reversed field (an angle turns the field's pattern, "
        "a field adds to it)",
    ),
    Channel(
        "field_along", "field_offset_t", "b_t", "T", 1e-9, MECHANICS, _field_along,
        _PER_ROW + " * " + _ALONG,
        "a magnetometer at the probe's position as the stage turns (a field that turns with the probe)",
    ),
    Channel(
        "field_across", "field_offset_t", "b_t", "T", 1e-9, MECHANICS, _field_across,
        _PER_ROW + " * " + _ACROSS,
        "a magnetometer at the probe's position as the stage turns (a field that turns with the probe)",
    ),
    Channel(
        "field_x", "field_offset_t", "b_t", "T", 1e-9, MECHANICS, _field_x, "np.multiply.outer({value}, (1.0, 0.0))",
        "a magnetometer at the probe's position (a field fixed in the lab, one that the reference misses)",
    ),
    Channel(
        "field_y", "field_offset_t", "b_t", "T", 1e-9, MECHANICS, _field_y, "np.multiply.outer({value}, (0.0, 1.0))",
        "a magnetometer at the probe's position (a field fixed in the lab, one that the reference misses)",
    ),
    Channel(
        "magnet_along", "magnet_offset_m", "d_m", "m", 1e-7, MECHANICS, _magnet_along,
        "np.multiply.outer({value}, (1.0, 0.0))",
        "the magnet's position on the lever measured (a microscope), or the gradient reversed (a position "
        "acts only through the gradient and curvature)",
    ),
    Channel(
        "magnet_across", "magnet_offset_m", "d_m", "m", 1e-7, MECHANICS, _magnet_across,
        "np.multiply.outer({value}, (0.0, 1.0))",
        "the magnet's position on the lever measured (a microscope), or the gradient reversed (a position "
        "acts only through the gradient and curvature)",
    ),
    Channel(
        "induced_moment", "energy_j", "alpha_am2_per_t", "A·m²/T", 1e-7, MECHANICS, _induced,
        "lambda arc: " + _PER_ROW + " * -0.5 * (arc.field_t * arc.direction).sum(-1) ** 2",
        "two field levels at one angle (an induced moment grows with B², a moment change with B)",
    ),
    Channel(
        "quartic_hinge", "energy_j", "k3_nm_per_rad3", "N·m/rad³", 1e-10, MECHANICS, _quartic,
        "lambda arc: " + _PER_ROW + " * 0.25 * arc.theta_rad**4",
        "ring-downs from several start swings in zero field (a hinge's energy grows with the swing)",
    ),
    Channel(
        "frequency", "frequency_hz", "c_hz", "Hz", 1e-6, READOUT, _frequency, "{value}",
        "none: an additive frequency is a readout term, not physics; find the physics that makes it",
        frozenset(),
    ),
)  # fmt: skip
FREQUENCY = CHANNELS[-1]
BY_NAME = {channel.name: channel for channel in CHANNELS}


def jacobians(
    fit: FitResult, table: MeasurementTable, weight: np.ndarray, channels: Sequence[Channel] = CHANNELS
) -> dict[str, np.ndarray]:
    """Each of ``channels``' weighted Jacobian w·∂f/∂p on ``table``'s rows (n,), beside ``fit``'s
    model at its fitted values (``weight`` w: the frequency's); one model evaluation each."""
    found = {}
    for channel in channels:
        found[channel.name] = (
            weight if channel is FREQUENCY else -fit.extension_columns(channel.jacobian_effect(), table)[:, 0]
        )
    return found
