"""Groups of candidates this table cannot tell apart, and the measurement that would.

- **Groups**: two candidates cannot be told apart by this data when their projected signatures
  span the same space (exact aliases, significant or not: gravity, an unreferenced field and a
  tilt of the plane in a field with constant Bz), or when both are significant (p < 0.01) and
  each one's fitted signal, v_A = P_A⊥·r (the residual's projection on A's projected
  signature), lies within the other's signature space: cos(v_A, span B⊥) ≥ 0.95 both ways.
  Groups are the connected sets of such pairs. Effects the model already holds and the effects
  they absorb are grouped by :mod:`mows.lab.aliases`.
- **Separating measurements**: the group's signatures and fitted signals (the fitted linear
  coefficients, extended) are evaluated on the table joined with a what-if variant of it
  (:mod:`mows.lab.diagnosis.what_if`); the cheapest variant after which no pair of the group stays
  indistinguishable is proposed. If none does, each member's independent check is reported
  (e.g. gravity and an unreferenced field act identically on the lever in every rotation: only
  levelling the plane or checking the reference's zero tells them apart).
- **Tie-break inside a group**: members within ΔBIC 2 of the group's best are ordered by
  (fitted parameters inside their physical bounds first, then catalog priority): physics whose
  size is fixed by known constants (static deflection, gravity, finite amplitude, damping,
  transverse gradient) before free calibration errors (field offset, plane tilt, moment scale).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Iterator

import numpy as np

from mows.lab import progress
from mows.lab.data.probe_rows import ProbeSet
from mows.lab.data.table import MeasurementTable
from mows.lab.diagnosis.candidates import ABSORBED, TIE_DELTA_BIC, Candidate
from mows.lab.diagnosis.physical_aliases import alias_statements
from mows.lab.diagnosis.projections import Signature, cosine_within, orthonormal_basis, project_out, same_span
from mows.lab.diagnosis.what_if import Variant, variants
from mows.lab.model.effects import Effect
from mows.lab.model.least_squares import FitResult, parameter_values

GROUP_COSINE = 0.95
GROUP_SIGNIFICANCE = 0.01
NEAR_ALIAS = 0.05  # an effect whose signature keeps less than this of its norm beside the model is absorbed
FREED = 0.5  # … by the model effect without which it keeps more than this


@dataclasses.dataclass
class Group:
    """Candidates this data cannot tell apart, the measurement that would, and direct checks."""

    number: int
    members: list[str]
    separated_by: str | None
    separation: str
    checks: list[str]
    aliases: list[str] = dataclasses.field(default_factory=list)  # exact physical aliases, in words and numbers
    in_model: list[str] = dataclasses.field(default_factory=list)  # members the model holds (absorbing the rest)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def _indistinguishable(a: Signature, b: Signature, significant: bool) -> bool:
    return same_span(a.basis, b.basis) or (
        significant
        and cosine_within(a.fitted_signal, b.basis) >= GROUP_COSINE
        and cosine_within(b.fitted_signal, a.basis) >= GROUP_COSINE
    )


def _clusters(candidates: list[Candidate]) -> list[list[Candidate]]:
    """Connected sets (of two or more) of indistinguishable candidates, each in tie-break order."""
    by_name = {c.name: c for c in candidates}
    significant = {c.name for c in candidates if c.p_value < GROUP_SIGNIFICANCE}
    parts = _partition({c.name: c.signature for c in candidates}, significant)
    return [_tie_break([by_name[name] for name in part]) for part in parts if len(part) > 1]


def group_candidates(
    candidates: list[Candidate], fit: FitResult, probes: ProbeSet, separate: bool = True
) -> list[Group]:
    """Number the groups by rank, put each group's members together in tie-break order
    (``candidates`` is reordered in place) and, with ``separate``, find what separates each group."""
    cluster_of = {c.name: members for members in _clusters(candidates) for c in members}
    ranked: list[Candidate] = []
    groups: list[Group] = []
    for candidate in candidates:
        members = cluster_of.get(candidate.name)
        if members is None:
            ranked.append(candidate)
        elif members[0] not in ranked:
            for member in members:
                member.group = len(groups) + 1
            ranked.extend(members)
            number = len(groups) + 1
            names = [c.name for c in members]
            groups.append(_separate(members, fit, probes, number) if separate else Group(number, names, None, "", []))
    candidates[:] = ranked
    return groups


def _tie_break(members: list[Candidate]) -> list[Candidate]:
    members = sorted(members, key=lambda c: -c.delta_bic)
    best = members[0].delta_bic
    tied = [c for c in members if c.delta_bic >= best - TIE_DELTA_BIC]
    rest = [c for c in members if c not in tied]
    return sorted(tied, key=lambda c: (not c.within_bounds, c.effect.priority)) + rest


def _partition(signatures: dict[str, Signature], significant: set[str]) -> list[list[str]]:
    """Connected sets of mutually indistinguishable signatures (names), singletons included;
    fitted signals are compared only between ``significant`` names."""
    names = list(signatures)
    parent = {name: name for name in names}

    def root(name: str) -> str:
        while parent[name] != name:
            name = parent[name]
        return name

    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            if _indistinguishable(signatures[a], signatures[b], a in significant and b in significant):
                parent[root(b)] = root(a)
    found: dict[str, list[str]] = {}  # root → the names in its set
    for name in names:
        found.setdefault(root(name), []).append(name)
    return list(found.values())


def _extended(
    fit: FitResult, members: list[Candidate], joined: MeasurementTable, coefficients: dict[str, np.ndarray]
) -> dict[str, Signature]:
    """The members' signatures on the ``joined`` what-if table, with their fitted signals
    extended by the same linear ``coefficients``."""
    model_basis = orthonormal_basis(fit.model_jacobian(joined))
    extended = {}
    for candidate in members:
        columns = np.asarray(fit.extension_columns(candidate.effect, joined))
        projected = project_out(columns, model_basis)
        basis = orthonormal_basis(projected, np.linalg.norm(columns, axis=0).max())
        extended[candidate.name] = Signature(
            basis, projected, 0.0, basis.shape[1], basis.T @ (projected @ coefficients[candidate.name])
        )
    return extended


def _separate(members: list[Candidate], fit: FitResult, probes: ProbeSet, number: int) -> Group:
    """The cheapest what-if variant that splits the group most; checks for what stays together."""
    names = [c.name for c in members]
    best_variant: Variant | None = None
    best_parts = [names]
    # The fitted signal extended to new rows: the same linear coefficients on the joined rows.
    coefficients = {
        c.name: np.linalg.lstsq(c.signature.projected, c.signature.fitted_signal, rcond=None)[0] for c in members
    }
    what_ifs = variants(fit.table, probes)
    for done, variant in enumerate(what_ifs):
        progress.stage(f"separating group {number} (what-if tables)", done, len(what_ifs))
        parts = _partition(
            _extended(fit, members, variant.table, coefficients),
            {c.name for c in members if c.p_value < GROUP_SIGNIFICANCE},
        )
        if len(parts) > len(best_parts):
            best_variant, best_parts = variant, parts
        if len(parts) == len(names):
            break
    together = [part for part in best_parts if len(part) > 1]
    checks = [
        f"{name}: {next(c for c in members if c.name == name).effect.check}" for part in together for name in part
    ]
    if best_variant is None:
        text = (
            "no variation of angles, amplitude, field or temperature separates them: they act identically "
            "on the lever; check directly"
        )
    else:
        text = f"{best_variant.description}: separates " + " | ".join(", ".join(part) for part in best_parts)
        if together:
            text += "; " + "; ".join(", ".join(part) for part in together) + " still act identically: check directly"
    fitted = {c.name: parameter_values(c.parameters) for c in members}
    return Group(
        number,
        names,
        None if best_variant is None else best_variant.name,
        text,
        checks,
        alias_statements(names, fit, probes, fitted),
    )


def absorbed_groups(
    fit: FitResult,
    effects: Iterable[Effect],
    candidates: list[Candidate],
    untestable: dict[str, str],
    probes: ProbeSet,
    first_number: int,
) -> list[Group]:
    """Groups of an effect the model holds with the catalog effects it absorbs: an effect not in
    the model whose signature lies in the model's span (all but NEAR_ALIAS of its norm) but not
    without that effect's columns (untested as "no signature … cannot already absorb", or a
    candidate left with almost nothing). With the exact aliases among them, the what-if variant
    after which the model no longer absorbs them, or the direct checks."""
    absorbing: dict[Effect, list[Effect]] = {}  # model effect → the effects it absorbs
    held_masks = list(_columns_without_each(fit))
    if not held_masks:
        return []
    model_basis = orthonormal_basis(fit.jacobian)
    # rank_candidates' signatures keep their columns
    known = {c.name: c.signature.columns for c in candidates if c.signature.columns is not None}
    for effect in effects:
        if effect.name in fit.model.effect_names or untestable.get(effect.name, ABSORBED) != ABSORBED:
            continue
        columns = known[effect.name] if effect.name in known else fit.extension_columns(effect)
        if not np.any(columns) or _kept(columns, model_basis) > NEAR_ALIAS:
            continue
        for held, keep in held_masks:
            if _kept(columns, orthonormal_basis(fit.jacobian[:, keep])) > FREED:
                absorbing.setdefault(held, []).append(effect)
    return [
        _absorbed_group(fit, held, absorbed, probes, first_number + i)
        for i, (held, absorbed) in enumerate(absorbing.items())
    ]


def _kept(columns: np.ndarray, basis: np.ndarray) -> float:
    """The fraction of the columns' norm outside the span of ``basis``."""
    size = np.linalg.norm(columns)
    return float(np.linalg.norm(project_out(columns, basis)) / size) if size > 0 else 0.0


def _columns_without_each(fit: FitResult) -> Iterator[tuple[Effect, np.ndarray]]:
    """(effect, column mask of ``fit.jacobian`` without that effect's parameters) for each
    effect of the model with free parameters."""
    owners = [None] + [e for e in fit.model.effects for _ in e.parameters]
    for effect in fit.model.effects:
        if effect.parameters:
            yield effect, np.array([owner is not effect for owner in owners])


def _absorbed_group(fit: FitResult, held: Effect, absorbed: list[Effect], probes: ProbeSet, number: int) -> Group:
    names = [held.name] + [e.name for e in absorbed]
    separated: list[str] = []
    variant_name: str | None = None
    for variant in variants(fit.table, probes):
        joined = variant.table
        model_basis = orthonormal_basis(fit.model_jacobian(joined))
        separated = [e.name for e in absorbed if _kept(fit.extension_columns(e, joined), model_basis) > NEAR_ALIAS]
        if separated:
            variant_name, description = variant.name, variant.description
            break
    together = [e for e in absorbed if e.name not in separated]
    text = (
        f"{held.label} is in the model and absorbs {', '.join(e.name for e in absorbed)}: they act (almost) "
        "identically on this table"
    )
    if separated:
        text += f"; {description}: separates {', '.join(separated)}"
    if together:
        text += f"; {', '.join(e.name for e in together)} still act identically: check directly"
    checks = [f"{e.name}: {e.check}" for e in [held] + together] if together else []
    return Group(number, names, variant_name, text, checks, alias_statements(names, fit, probes), [held.label])
