"""Probe constants and their calibration from the weak-field sensitivity.

The probe is a torsional oscillator: a magnet of moment ``m`` and mass ``a`` at the end of a
lever ``l`` on a spring ``kM``, with inertia ``J`` and damping ``δ`` (paper, Fig. S1).
Equation numbers are those of "Miniature magneto-oscillatory wireless sensor for magnetic field
and gradient measurements", F. Fischer, M. Jeong, T. Qiu (docs/physics.md §1).
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Callable, Iterable

import numpy as np
import yaml

from mows.physics import ranges
from mows.physics.schema import FloatOrArray, SchemaError, finite_number, load_yaml, refused
from mows.records.files import writing

#: How far a probe's constants may lie from the paper's before they are called implausible:
#: wide for a new cantilever, narrow against a unit error (a factor of 1000).
PLAUSIBLE_FACTOR = 100.0


def spring_from_beta0(f00_hz: float, moment_am2: float, beta0_hz_per_t: float) -> float:
    """Mechanical spring constant kM = f00·m / (2·β0), in N·m/rad (Eq. 9 inverted)."""
    return f00_hz * moment_am2 / (2.0 * beta0_hz_per_t)


def inertia_from_beta0(moment_am2: float, beta0_hz_per_t: float, f00_hz: float) -> float:
    """Moment of inertia J = m / (8π²·β0·f00), in kg·m² (Eq. 10).

    Like the paper, this neglects damping: it is exact for J·(2π·f00)² = kM.
    """
    return moment_am2 / (8.0 * math.pi**2 * beta0_hz_per_t * f00_hz)


DEFAULT_BETA0_REL_STD = 0.01  # a probe file that does not say how well β0 is known: 1 %
DEFAULT_THETA_STOP_STD_RAD = math.radians(1.0)  # … nor how well its stop is: 1°
# Probe-file keys written only where they differ from these (older files read as they did).
UNSET_BY_DEFAULT = {
    "moment_temp_coeff_per_k": 0.0,
    "beta0_rel_std": DEFAULT_BETA0_REL_STD,
    "theta_stop_std_rad": DEFAULT_THETA_STOP_STD_RAD,
}


def lever_from_inertia(inertia_kgm2: float, magnet_mass_kg: float) -> float:
    """Lever length l = √(J/a) of the point-mass model J = a·l² (Eq. S1), in metres."""
    return math.sqrt(inertia_kgm2 / magnet_mass_kg)


@dataclasses.dataclass(frozen=True)
class Probe:
    """Physical constants of one MOWS probe, SI units.

    Parameters
    ----------
    moment_am2 : magnetic moment m, A·m².
    spring_nm_per_rad : mechanical spring kM at ``reference_temperature_k``, N·m/rad.
    inertia_kgm2 : moment of inertia J about the pivot, kg·m².
    lever_m : distance l from pivot to magnet, m. Not forced to √(J/a): a real lever has
        inertia of its own, and l and a enter the physics separately (gradient and gravity).
    magnet_mass_kg : magnet mass a, kg.
    damping_per_s : amplitude decay rate δ of Eq. S2, 1/s.
    theta_stop_rad : housing stop θmax, rad (calibrated 24° in the paper).
    spring_temp_coeff_per_k : relative change of kM per kelvin (spring steel ≈ −2.6e-4).
    reference_temperature_k : temperature at which kM and m are given, K.
    moment_temp_coeff_per_k : relative change of m per kelvin (NdFeB ≈ −1.2e-3; 0 keeps m fixed).
    beta0_rel_std : relative standard uncertainty of m/kM (β0) from the calibration (1 % where
        the file does not say); what the model lab allows a moment-scale error to be.
    theta_stop_std_rad : standard uncertainty of the housing stop, rad (1° where the file does
        not say); what the model lab allows the stop to move.
    """

    moment_am2: float
    spring_nm_per_rad: float
    inertia_kgm2: float
    lever_m: float
    magnet_mass_kg: float
    damping_per_s: float = 1.8
    theta_stop_rad: float = math.radians(24.0)
    spring_temp_coeff_per_k: float = -2.6e-4
    reference_temperature_k: float = 293.15
    moment_temp_coeff_per_k: float = 0.0
    beta0_rel_std: float = DEFAULT_BETA0_REL_STD
    theta_stop_std_rad: float = DEFAULT_THETA_STOP_STD_RAD

    def __post_init__(self) -> None:
        for name in (
            "moment_am2",
            "spring_nm_per_rad",
            "inertia_kgm2",
            "lever_m",
            "magnet_mass_kg",
            "reference_temperature_k",
        ):
            _require(name, getattr(self, name), lambda v: v > 0, "> 0")
        _require("damping_per_s", self.damping_per_s, lambda v: v >= 0, ">= 0")
        ranges.check("magnet_mass_kg", self.magnet_mass_kg)
        ranges.check("temperature_k", self.reference_temperature_k, "reference_temperature_k")
        _require("theta_stop_rad", self.theta_stop_rad, lambda v: 0 < v < math.pi / 2, "in (0, pi/2)")
        _require("beta0_rel_std", self.beta0_rel_std, lambda v: 0 < v < 1, "in (0, 1)")
        _require("theta_stop_std_rad", self.theta_stop_std_rad, lambda v: 0 < v < math.pi / 4, "in (0, pi/4)")
        for name in ("spring_temp_coeff_per_k", "moment_temp_coeff_per_k"):
            _require(name, getattr(self, name), lambda v: abs(v) < 1e-2, "with |value| < 1e-2 per K")
        if self.damping_per_s**2 >= self.spring_nm_per_rad / self.inertia_kgm2:
            raise SchemaError(
                "damping_per_s",
                f"= {self.damping_per_s} makes the probe overdamped "
                f"(needs δ² < kM/J = {self.spring_nm_per_rad / self.inertia_kgm2:.4g} s⁻²)",
            )

    @property
    def f00_hz(self) -> float:
        """Zero-field ring-down frequency f00 = √(kM/J − δ²)/2π, Hz (Eq. S1 at B = G = 0)."""
        return float(self.frequency_for_spring_hz(self.spring_nm_per_rad))

    def frequency_for_spring_hz(self, spring_nm_per_rad: FloatOrArray) -> FloatOrArray:
        """Damped frequency √(k/J − δ²)/2π for a total stiffness k (Eq. S1); NaN where k/J ≤ δ²."""
        omega2 = np.asarray(spring_nm_per_rad, dtype=float) / self.inertia_kgm2 - self.damping_per_s**2
        return np.sqrt(np.where(omega2 > 0, omega2, np.nan)) / math.tau

    @property
    def beta0_hz_per_t(self) -> float:
        """Weak-field sensitivity β0 = f00·m/(2kM), Hz/T (Eq. 9)."""
        return self.f00_hz * self.moment_am2 / (2.0 * self.spring_nm_per_rad)

    @property
    def gamma0_hz_m_per_t(self) -> float:
        """Weak-gradient sensitivity γ0 = β0·l, Hz·m/T (Eqs. 5, 8, 9)."""
        return self.beta0_hz_per_t * self.lever_m

    @property
    def cancellation_field_t(self) -> float:
        """Field along the probe axis at which f → 0: B = −kM/m, tesla (main text after Eq. 8)."""
        return -self.spring_nm_per_rad / self.moment_am2

    def spring_at(self, temperature_k: FloatOrArray) -> FloatOrArray:
        """kM at ``temperature_k``: kM·(1 + α·(T − T_ref)), N·m/rad (docs/physics.md §9.6)."""
        return self.spring_nm_per_rad * (
            1.0 + self.spring_temp_coeff_per_k * (temperature_k - self.reference_temperature_k)
        )

    def at_temperature(self, temperature_k: float) -> Probe:
        """This probe with its magnet's moment at ``temperature_k``: m·(1 + α·(T − T_ref)).

        Only the moment changes: kM keeps its own coefficient (:meth:`spring_at`), and the mass
        and lever, hence gravity's torque, do not depend on temperature. ValueError where the
        moment would not stay positive.
        """
        if self.moment_temp_coeff_per_k == 0.0:
            return self
        return self.replace(
            moment_am2=self.moment_am2
            * (1.0 + self.moment_temp_coeff_per_k * (temperature_k - self.reference_temperature_k))
        )

    def replace(self, **changes: float) -> Probe:
        return dataclasses.replace(self, **changes)

    @classmethod
    def from_calibration(
        cls, moment_am2: float, f00_hz: float, beta0_hz_per_t: float, magnet_mass_kg: float, **others: float
    ) -> Probe:
        """Probe from the paper's calibration: β0 gives kM (Eq. 9) and J (Eq. 10), J and a give l.

        J is taken from the damped relation J = kM / ((2π·f00)² + δ²), so that the
        probe's ``f00_hz`` reproduces the calibrated f00 exactly; Eq. 10 (which neglects
        δ) differs from it by δ²/(2π·f00)² ≈ 6.5e-6 for the paper's device.
        """
        spring = spring_from_beta0(f00_hz, moment_am2, beta0_hz_per_t)
        damping = others.get("damping_per_s", cls.damping_per_s)
        inertia = spring / ((math.tau * f00_hz) ** 2 + damping**2)
        lever = others.pop("lever_m", None) or lever_from_inertia(inertia, magnet_mass_kg)
        return cls(
            moment_am2=moment_am2,
            spring_nm_per_rad=spring,
            inertia_kgm2=inertia,
            lever_m=lever,
            magnet_mass_kg=magnet_mass_kg,
            **others,
        )

    # --- YAML -----------------------------------------------------------------------------
    @classmethod
    def from_dict(cls, data: dict) -> Probe:
        """Probe from the probe-file keys (see ``to_dict``).

        ``f00_hz`` may replace one of ``spring_nm_per_rad`` or ``inertia_kgm2``; when all three
        are given they must agree with Eq. S1 to 1e-4, otherwise the file contradicts itself.
        ``theta_stop_deg`` is accepted for ``theta_stop_rad`` (and ``theta_stop_std_deg`` for
        ``theta_stop_std_rad``). A ``calibration`` mapping (how the
        constants were measured: :func:`calibration_record`) is not a constant and is skipped.
        Every value must be a finite number (YAML 1.2's ``7e-6`` is one).
        """
        if not isinstance(data, dict):
            raise ValueError(f"a probe file is a mapping of constants, got {type(data).__name__}")
        data = dict(data)
        if not isinstance(data.pop("calibration", {}), dict):
            raise ValueError("the probe file's 'calibration' section must be a mapping")
        allowed = {f.name for f in dataclasses.fields(cls)} | {"f00_hz", "theta_stop_deg", "theta_stop_std_deg"}
        unknown = set(data) - allowed
        if unknown:
            raise ValueError(f"unknown probe keys {sorted(unknown)}; allowed: {sorted(allowed)}")
        for key, value in data.items():  # before anything is derived from them: a NaN f00_hz is f00_hz's
            finite_number(key, value)
        if "theta_stop_deg" in data and "theta_stop_rad" in data:
            raise ValueError("theta_stop_deg and theta_stop_rad are both given: give one of them")
        if "theta_stop_deg" in data:
            data["theta_stop_rad"] = math.radians(data.pop("theta_stop_deg"))
        if "theta_stop_std_deg" in data and "theta_stop_std_rad" in data:
            raise ValueError("theta_stop_std_deg and theta_stop_std_rad are both given: give one of them")
        if "theta_stop_std_deg" in data:
            data["theta_stop_std_rad"] = math.radians(data.pop("theta_stop_std_deg"))
        f00 = data.pop("f00_hz", None)
        damping = data.get("damping_per_s", cls.damping_per_s)
        omega2 = None if f00 is None else (math.tau * f00) ** 2 + damping**2
        if "spring_nm_per_rad" not in data and omega2 is not None and "inertia_kgm2" in data:
            data["spring_nm_per_rad"] = data["inertia_kgm2"] * omega2
        if "inertia_kgm2" not in data and omega2 is not None and "spring_nm_per_rad" in data:
            data["inertia_kgm2"] = data["spring_nm_per_rad"] / omega2
        if "lever_m" not in data and "inertia_kgm2" in data and "magnet_mass_kg" in data:
            data["lever_m"] = lever_from_inertia(data["inertia_kgm2"], data["magnet_mass_kg"])
        missing = {"moment_am2", "spring_nm_per_rad", "inertia_kgm2", "lever_m", "magnet_mass_kg"} - set(data)
        if missing:
            raise ValueError(
                f"probe file lacks {sorted(missing)} (f00_hz can stand in for spring_nm_per_rad or inertia_kgm2)"
            )
        probe = cls(**{k: float(v) for k, v in data.items()})
        if f00 is not None and abs(probe.f00_hz / f00 - 1.0) > 1e-4:
            raise SchemaError(
                "f00_hz",
                f"= {f00} contradicts spring_nm_per_rad, inertia_kgm2 and damping_per_s, "
                f"which give √(kM/J − δ²)/2π = {probe.f00_hz:.6f} Hz (Eq. S1)",
            )
        implausible = probe.implausible()
        if implausible:
            raise ValueError(f"implausible probe constants, probably a unit error: {'; '.join(implausible)}")
        return probe

    def to_dict(self) -> dict:
        """The probe-file keys; ``moment_temp_coeff_per_k`` and the uncertainties only where they
        are set, so that the files of probes without them read as they always did."""
        data = {f.name: float(getattr(self, f.name)) for f in dataclasses.fields(self)}
        for name, unset in UNSET_BY_DEFAULT.items():
            if data[name] == unset:
                del data[name]
        data["f00_hz"] = float(self.f00_hz)
        return data

    @classmethod
    def from_yaml(cls, path: str | os.PathLike[str]) -> Probe:
        """The probe file at ``path`` (:meth:`from_dict`); ValueError naming the file, the key and the value."""
        return load_yaml(path, "probe file", cls.from_dict)

    def to_yaml(
        self,
        path: str | os.PathLike[str],
        calibration: dict | None = None,
        inputs: Iterable[str | os.PathLike[str]] = (),
        force: bool = False,
    ) -> str:
        """Write the probe file (:func:`yaml_text`) as a new file, never over ``inputs`` nor, unless
        ``force``, over an existing one (:func:`mows.records.files.writing`); "wrote PATH" or
        "replaced PATH"."""
        with writing([path], inputs, force) as outputs:
            outputs.temporaries[0].write_text(self.yaml_text(calibration))
        return outputs.report()

    def yaml_text(self, calibration: dict | None = None) -> str:
        """The probe file's text; ``calibration`` (uncertainties, correlations, date, hardware id)
        is its ``calibration`` section."""
        data = self.to_dict() if calibration is None else {**self.to_dict(), "calibration": calibration}
        return yaml.safe_dump(data, sort_keys=False, allow_unicode=True)

    def implausible(self) -> list[str]:
        """The constants more than PLAUSIBLE_FACTOR away from the paper's probe, each with its
        value and band: a millimetre cantilever does not reach them, a unit error does (mA read
        as A, kHz as Hz, mm as m)."""
        return [
            f"{name} = {value:.4g} (plausible {reference / PLAUSIBLE_FACTOR:.3g} to {reference * PLAUSIBLE_FACTOR:.3g})"
            for name, value, reference in (
                (name, getattr(self, name), getattr(PAPER_PROBE, name))
                for name in ("moment_am2", "spring_nm_per_rad", "inertia_kgm2", "lever_m", "beta0_hz_per_t")
            )
            if not reference / PLAUSIBLE_FACTOR <= value <= reference * PLAUSIBLE_FACTOR
        ]


def calibration_record(path: str | os.PathLike[str]) -> dict | None:
    """The ``calibration`` section of a probe file (None if the file has none)."""
    return load_yaml(path, "probe file", lambda data: data.get("calibration") if isinstance(data, dict) else None)


def _require(name: str, value: object, ok: Callable[[float], bool], what: str) -> None:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and ok(value)):
        raise refused(name, value, f"is out of range: must be finite and {what}")


#: The paper's device (docs/physics.md §10): m = 0.89 mA·m², f00 = 112.48 Hz, β0 = 3.68 Hz/mT,
#: a = 7.2 mg, δ = 1.8 1/s. Gives kM = 1.360e-5 N·m, J = 2.723e-11 kg·m², l = 1.945 mm.
PAPER_PROBE = Probe.from_calibration(
    moment_am2=0.89e-3,
    f00_hz=112.48,
    beta0_hz_per_t=3.68e3,
    magnet_mass_kg=7.2e-6,
    damping_per_s=1.8,
    theta_stop_rad=math.radians(24.0),
)
