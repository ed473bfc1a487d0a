"""What a term beyond the catalog means: its family, its physical reading, and the readings that
fit the rows as well, each with the measurement that would tell them apart.

A term is a channel of the potential times a monomial of the covariates (:mod:`.channels`). Its
family is the channel and the kinds of the monomial's factors (``moment_temperature``,
``spring_current_squared``, ``field_x_current``); every family has a reading, the particular one
where a mechanism of MOWS probes, stages and benches is known to act so (:data:`READINGS`), else
the channel changing with the covariates, in words. A product of an angle harmonic with a field or
a current, or of two fields, is then no separate family: it is a field (lab frame) that follows
the current, a moment that follows the field, and so on, in the channel where it acts.

Several channels can make nearly the same signature on a table's rows: a moment that falls with
temperature and a reference sensor whose gain drifts with it scale the field's spring alike in a
uniform field. :func:`alternatives` lists every term of another channel whose column is so close
to the reported one that swapping them changes χ² by less than :data:`DISTINGUISH_CHI2`, with the
measurement that would tell the two apart (the channel's ``tells_apart``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from mows.lab.diagnosis.discovery.channels import Channel
from mows.lab.diagnosis.discovery.library import factor, kinds
from mows.lab.diagnosis.discovery.selection import Searched

DISTINGUISH_CHI2 = 9.0  # swapping a reading for another changes χ² by less: the rows cannot tell (3σ)

CHANNEL_WORDS = {
    "moment": "the magnet's moment",
    "spring": "the hinge's spring",
    "field_along": "a field along the lever that turns with the probe",
    "field_across": "a field across the lever that turns with the probe",
    "field_x": "a field along the lab's x that the reference misses",
    "field_y": "a field along the lab's y that the reference misses",
    "angle": "the probe's angle",
    "magnet_along": "the magnet's position along the lever",
    "magnet_across": "the magnet's position across the lever",
    "induced_moment": "a moment induced along the lever (U ∋ −½·α·(u·B)²)",
    "quartic_hinge": "a stiffening hinge (U ∋ ¼·k3·θ⁴)",
    "frequency": "an additive frequency (a readout term, no physics)",
}
KIND_WORDS = {
    "field": "the field",
    "field_z": "the out-of-plane field",
    "gradient": "the gradient",
    "temperature": "temperature",
    "time": "time",
    "current": "the coil current",
    "swing": "the swing",
    "angle": "the stage's angle",
}
_FIELD_CURRENT = "the coil makes a field the reference misses (its constant or axis is off, or its leads' field)"
_FIELD_TEMPERATURE = (
    "a magnetised part near the probe whose field changes with temperature, or the sensor's offset drift"
)
_FIELD_FIELD = "the reference sensor's gain or axes are off: a field error in proportion to the field"
_TURNING = "a field that turns with the probe (a magnetised part on the stage)"
# (channel, kinds of the monomial) → the physical reading where a known mechanism acts so.
READINGS: dict[tuple[str, tuple[str, ...]], str] = {
    ("moment", ()): "the moment is off (the catalog's moment_scale)",
    ("moment", ("temperature",)): "the moment's temperature coefficient (NdFeB ≈ −1e-3/K)",
    ("moment", ("temperature", "temperature")): "the moment's temperature coefficient, curved",
    ("moment", ("time",)): "the moment ageing or demagnetising",
    ("moment", ("current",)): "the coil's field magnetises the magnet (a reversible moment ∝ I)",
    ("moment", ("current", "current")): "the coil's Ohmic heat warms the magnet: its moment falls ∝ I²",
    ("moment", ("field",)): "induced magnetisation (a susceptibility): a moment that grows with the field",
    ("moment", ("current", "temperature")): "the coil's heat and the room's both warm the magnet",
    ("spring", ()): "the spring is off (the zero-field frequency f00 takes it)",
    ("spring", ("temperature",)): "the spring's temperature coefficient (the catalog's thermal drift)",
    ("spring", ("temperature", "temperature")): "the spring's temperature coefficient, curved",
    ("spring", ("time",)): "spring creep or drift (the catalog's spring drift)",
    ("spring", ("time", "time")): "spring creep or drift, curved",
    ("spring", ("temperature", "time")): "a spring drift whose rate depends on temperature",
    ("spring", ("current",)): "the coil's field acts on a magnetic part of the hinge",
    ("spring", ("current", "current")): "the coil's Ohmic heat warms the spring",
    ("spring", ("swing", "swing")): "a non-linear (stiffening) hinge",
    ("spring", ("field", "field")): "a soft-magnetic hinge or lever: the field stiffens it",
    ("field_x", ()): "a field fixed in the lab that the reference misses (the catalog's field_offset)",
    ("field_y", ()): "a field fixed in the lab that the reference misses (the catalog's field_offset)",
    ("field_x", ("current",)): _FIELD_CURRENT,
    ("field_y", ("current",)): _FIELD_CURRENT,
    ("field_x", ("temperature",)): _FIELD_TEMPERATURE,
    ("field_y", ("temperature",)): _FIELD_TEMPERATURE,
    ("field_x", ("time",)): "a field the reference misses that drifts (a magnetised part relaxing)",
    ("field_y", ("time",)): "a field the reference misses that drifts (a magnetised part relaxing)",
    ("field_x", ("field",)): _FIELD_FIELD,
    ("field_y", ("field",)): _FIELD_FIELD,
    ("field_along", ()): _TURNING,
    ("field_across", ()): _TURNING,
    ("field_along", ("field",)): _FIELD_FIELD,
    ("field_across", ("field",)): _FIELD_FIELD,
    ("field_along", ("current",)): "the coil's field at the probe differs from the reference's (its position)",
    ("field_across", ("current",)): "the coil's field at the probe differs from the reference's (its position)",
    ("angle", ()): "the probe's angle is off (the catalog's angle_offset)",
    ("angle", ("temperature",)): "the mount turns with temperature (thermal expansion of the mount)",
    ("angle", ("time",)): "the probe slips in its mount or the stage creeps",
    ("angle", ("current",)): "the coil's force or heat turns the mount",
    ("angle", ("field",)): "the field's torque twists a compliant mount",
    ("magnet_along", ()): "the magnet sits off its nominal place along the lever (glued off, or the lever's length)",
    ("magnet_across", ()): "the magnet sits off the lever's axis (glued off centre)",
    ("magnet_along", ("temperature",)): "the lever expands with temperature",
    ("induced_moment", ()): "a moment induced along the lever (a soft-magnetic lever, or the magnet's susceptibility)",
    ("induced_moment", ("temperature",)): "an induced moment whose susceptibility changes with temperature",
    ("quartic_hinge", ()): "a stiffening hinge",
    ("quartic_hinge", ("temperature",)): "a stiffening hinge that changes with temperature",
    (
        "frequency",
        ("angle",),
    ): "geometry: a field the reference misses, a tilt, an angle offset (through the potential)",
    ("frequency", ("angle", "field")): _FIELD_FIELD,
    ("frequency", ("angle", "current")): _FIELD_CURRENT,
    ("frequency", ("field", "field")): "induced magnetisation (a susceptibility): a moment that grows with the field",
}


def family(channel: Channel, factors: Sequence[str]) -> str:
    """The channel and the kinds of the monomial: ``moment_temperature``, ``spring_current_squared``."""
    words: list[str] = []
    for kind in dict.fromkeys(kinds(factors)):
        count = kinds(factors).count(kind)
        words.append(kind + ("_squared" if count == 2 else ""))
    return "_".join([channel.name, *words])


def reading(channel: Channel, factors: Sequence[str]) -> str:
    """The physical reading of a term (module docstring); never empty."""
    found = READINGS.get((channel.name, kinds(factors)))
    if found:
        return found
    if not factors:
        return CHANNEL_WORDS[channel.name]
    covariates = " and ".join(
        dict.fromkeys(KIND_WORDS.get(factor(name).kind, f"the column {name}") for name in factors)
    )
    return f"{CHANNEL_WORDS[channel.name]} changes with {covariates}"


def alternatives(searched: Searched, index: int, gain_chi2: float) -> list[str]:
    """The readings of other channels that fit the rows as well as term ``index`` of ``searched``
    (module docstring), the closest per channel, each with the measurement that tells them apart."""
    term = searched.terms[index]
    cosines = np.abs(searched.every_unit.T @ searched.unit[:, index])
    found: dict[str, str] = {}
    for j in np.argsort(-cosines):
        other = searched.every[j]
        if gain_chi2 * (1.0 - cosines[j] ** 2) > DISTINGUISH_CHI2:
            break
        if other.channel.name in found or other.channel.name == term.channel.name:
            continue
        found[other.channel.name] = (
            f"{other.name} ({reading(other.channel, other.factors)}); to tell apart: "
            f"{term.channel.tells_apart if other.channel.name == 'frequency' else other.channel.tells_apart}"
        )
    return list(found.values())
